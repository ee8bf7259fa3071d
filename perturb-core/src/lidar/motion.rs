//! Motion and alignment family (L-F): ego-motion blur, moving objects, ghost points, misalignment.
