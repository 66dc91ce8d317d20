"""Navigation helpers for code that drives a robot: the seeds' EKF (``ekf``: wheel
odometry and a z-gyro fused as robot_localization's ``ekf_node`` does), scan-to-scan
ICP lidar odometry (``icp``) and a pure-pursuit path follower (``pure_pursuit``). The
scenario runner (``wcdrive.sim``) uses them for its closed-loop runs; they need no
simulator."""
