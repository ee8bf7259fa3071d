//! Pattern family (C-E): graphic occlusions drawn over the image.
