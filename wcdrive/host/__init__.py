"""The host side: the session with the board, telemetry, odometry, the Wheelchair and Robot APIs."""
