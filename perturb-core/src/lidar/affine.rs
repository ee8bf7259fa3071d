//! Affine family (L-E): shear, scale and rotation of the points inside object boxes.
