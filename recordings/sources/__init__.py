"""Where sessions come from besides the simulator, and where they go.

- :mod:`~recordings.sources.video`: a video file or a camera as frames (OpenCV);
- :mod:`~recordings.sources.bags`: ROS 2 and ROS 1 bags (and Foxglove MCAP files) read;
- :mod:`~recordings.sources.segmentation`: cutting frames without a step clock into steps;
- :mod:`~recordings.sources.importer`: frames of a video, a camera or a bag written as one
  sensor-only session;
- :mod:`~recordings.sources.ros_export`: a session written as a rosbag2 folder.
"""
