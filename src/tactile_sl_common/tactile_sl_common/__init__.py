"""What every tactile-sl package shares: message formats, bags, safe files, the pad's elasticity.

Plain Python (no rclpy): :mod:`.images`, :mod:`.camera_info` and :mod:`.clouds` describe
messages as dicts of plain values, :mod:`.bag_io` reads and writes rosbag2 MCAP files,
:mod:`.safe_files` writes outputs without ever destroying a user's file, and
:mod:`.elasticity` holds the elastic pad's Green's functions that both the touch stage and the
simulator use.  The rclpy helpers every node uses are in :mod:`tactile_sl_common.nodes`.
"""
