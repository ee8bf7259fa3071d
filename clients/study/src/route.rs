//! The reference route: a polyline in the pose frame, with arc length, signed lateral offset and
//! curvature. The geometry is `perturb_core::route` (campaigns project the vehicle on a route
//! with it too); this module reads routes from files with the study's errors.

use crate::error::{Result, StudyError};
pub use perturb_core::route::{Projection, Route};
use std::path::Path;

/// Reads a route from a CSV of points (see [`read_xy_csv`]).
pub fn load(path: &Path) -> Result<Route> {
    let points = read_xy_csv(path)?;
    Route::new(points).map_err(|reason| StudyError::Route {
        path: path.to_path_buf(),
        reason,
    })
}

/// Reads points from a CSV with columns `x,y` (a header naming them, in any position, or no
/// header and x, y as the first two columns). Lines starting with `#` are comments.
pub fn read_xy_csv(path: &Path) -> Result<Vec<[f64; 2]>> {
    let text = std::fs::read_to_string(path).map_err(StudyError::io(path))?;
    perturb_core::route::parse_xy_csv(&text).map_err(|reason| StudyError::Route {
        path: path.to_path_buf(),
        reason,
    })
}
