"""ROS 2 messages from the chair: MCAP recordings, the Foxglove live view, the port tap."""
