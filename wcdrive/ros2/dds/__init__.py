"""The chair on a live ROS 2 graph over DDS, without a ROS install (docs/ros2.md).

``types``: cyclonedds IDL classes generated from ROS 2 Jazzy's message definitions
(rosbags' type store), with their RIHS01 hashes. ``qos``: ROS 2's QoS profiles as
DDS QoS, the type hash in each endpoint's USER_DATA. ``config``: the Cyclone DDS
configuration (this host only by default, the LAN on request). ``graph``: a ROS 2
node on DDS (``rt/`` topics, ``ros_discovery_info``). ``cmdvel``: which ``/cmd_vel``
samples may drive. ``node``: a ``Robot`` on that graph. Nothing here imports
cyclonedds at module load but ``types``, ``qos`` and ``graph``, so a missing DDS
stack is reported by ``graph.open_participant`` with what to install.
"""
