//! Distortion family (C-D): geometric and sharpness changes.
