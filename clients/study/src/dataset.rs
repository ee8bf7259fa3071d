//! Datasets for the batch commands: a folder of images, a folder of point-cloud files, or a bag.

use crate::error::{Result, StudyError};
use perturb_core::formats::FileKind;
use perturb_core::registry::Modality;
use std::path::{Path, PathBuf};

/// A dataset to perturb.
pub enum Dataset {
    /// Files of one modality, sorted by path (the index is the frame's sequence number).
    Files {
        /// The folder.
        root: PathBuf,
        /// Paths relative to `root`.
        files: Vec<PathBuf>,
        /// Camera or LiDAR.
        modality: Modality,
    },
    /// A rosbag2 MCAP bag (file or directory).
    Bag(PathBuf),
}

fn is_bag_dir(p: &Path) -> bool {
    p.join("metadata.yaml").exists()
        || std::fs::read_dir(p)
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .any(|e| e.path().extension().is_some_and(|x| x == "mcap"))
            })
            .unwrap_or(false)
}

fn walk(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .map_err(StudyError::io(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(root, &p, out)?;
        } else if FileKind::from_path(&p).is_ok_and(|k| k != FileKind::Mcap) {
            out.push(p.strip_prefix(root).expect("under root").to_path_buf());
        }
    }
    Ok(())
}

impl Dataset {
    /// Recognises the dataset at `path`.
    pub fn open(path: &Path) -> Result<Self> {
        if path.is_file() {
            if FileKind::from_path(path)? == FileKind::Mcap {
                return Ok(Dataset::Bag(path.to_path_buf()));
            }
            return Err(StudyError::input(
                path,
                "is a single file; use `perturb apply` for one file, or give a folder or a bag",
            ));
        }
        if !path.is_dir() {
            return Err(StudyError::input(path, "does not exist"));
        }
        if is_bag_dir(path) {
            return Ok(Dataset::Bag(path.to_path_buf()));
        }
        let mut files = Vec::new();
        walk(path, path, &mut files)?;
        if files.is_empty() {
            return Err(StudyError::input(
                path,
                "holds no image (.png .jpg) or point-cloud (.bin .pcd .pcd.bin) file",
            ));
        }
        let kinds: Vec<bool> = files
            .iter()
            .map(|f| {
                FileKind::from_path(f)
                    .map(|k| k.is_image())
                    .unwrap_or(false)
            })
            .collect();
        let images = kinds.iter().filter(|&&b| b).count();
        if images != 0 && images != files.len() {
            return Err(StudyError::input(
                path,
                format!(
                    "mixes images ({images}) and point clouds ({}); give one modality per folder",
                    files.len() - images
                ),
            ));
        }
        Ok(Dataset::Files {
            root: path.to_path_buf(),
            modality: if images > 0 {
                Modality::Camera
            } else {
                Modality::Lidar
            },
            files,
        })
    }
}
