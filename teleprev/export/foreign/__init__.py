"""Import: robot recordings that teleprev did not write (ROS 2 MCAP, rosbag2 folders, Foxglove-schema MCAP)
into LeRobot datasets, through the same exporter as teleprev's own sessions.

A foreign file is opened as a reader with SessionReader's surface (topics with teleprev's schema names,
messages decoded into teleprev payloads, episodes), so export/session.py plans and writes it exactly as
it does a session: config.py reads the import recipe, ros.py and foxglove.py read the two families of
files, episodes.py cuts episodes, run.py puts it together.
"""
