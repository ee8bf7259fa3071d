//! The lightweight weather approximations of the paper (L-A4 snow, L-A6 rain, L-A9 fog).
