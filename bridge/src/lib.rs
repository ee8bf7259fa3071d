//! # perturb-bridge
//!
//! Connects the perturbation middleware to the outside world: ROS 2 topics in and out over DDS,
//! ROS 1 topics over TCPROS, bag replay (rosbag2 MCAP, ROS 1 `.bag` and ROS 1 MCAP;
//! hardware-in-the-loop) and recording (rosbag2 MCAP or ROS 1 `.bag`), and a synthetic camera
//! and VLP-32C.
//!
//! Every adapter is a thread that talks to a [`bus::Bus`]: sources publish into
//! `<stream>/raw`, sinks read `<stream>/perturbed`, and `perturbd` sits in between.

pub mod adapter;
pub mod bus;
pub mod camera_info;
pub mod config;
pub mod daemon_link;
pub mod dds;
pub mod egress;
pub mod endpoint;
pub mod events;
pub mod frame;
pub mod guard;
pub mod ingress;
pub mod iox;
pub mod kill;
pub mod msgs;
pub mod pose;
pub mod record;
pub mod replay;
pub mod ros1;
pub mod run;
pub mod stats;
pub mod synthetic;
pub mod topic;
pub mod view;
