//! The LiDAR clustering detector (Autoware Mini style): ground removal, voxel downsampling, DBSCAN, box fitting.
