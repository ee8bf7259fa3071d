"""perturbd and perturb-bridge under ROS 2 launch, each respawned at once when it ends:

    ros2 launch config/ros2/perturb.launch.py daemon_config:=/etc/perturb/perturbd.toml \
        bridge_config:=/etc/perturb/bridge.toml

While perturbd restarts the bridge passes raw frames (docs/safety.md)."""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration


def generate_launch_description():
    daemon = LaunchConfiguration("daemon_config")
    bridge = LaunchConfiguration("bridge_config")
    state = LaunchConfiguration("state_dir")
    return LaunchDescription([
        DeclareLaunchArgument("daemon_config", default_value="/etc/perturb/perturbd.toml"),
        DeclareLaunchArgument("bridge_config", default_value="/etc/perturb/bridge.toml"),
        DeclareLaunchArgument("state_dir", default_value="/var/lib/perturb"),
        ExecuteProcess(cmd=["perturbd", "--config", daemon, "--report", [state, "/perturbd-report.json"]],
                       output="screen", respawn=True, respawn_delay=0.0, sigterm_timeout="10"),
        ExecuteProcess(cmd=["perturb-bridge", "--config", bridge, "--report", [state, "/bridge-report.json"]],
                       output="screen", respawn=True, respawn_delay=0.0, sigterm_timeout="10"),
    ])
