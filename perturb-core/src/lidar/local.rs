//! Local family (L-D): corruptions of the points inside object boxes.
