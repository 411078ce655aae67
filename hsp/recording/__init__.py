"""Recordings: episodes as MCAP files of ROS 2 messages, as ``ros2 bag record`` writes them."""
