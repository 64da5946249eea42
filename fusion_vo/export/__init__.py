"""Results in the formats of other tools: a run's trajectories as ROS 2 bags (rosbag2 and MCAP).

See :mod:`fusion_vo.export.ros`.
"""

from fusion_vo.export.ros import FORMATS, ExportTrajectory, export_run, export_trajectories, read_pose_covariances

__all__ = ["FORMATS", "ExportTrajectory", "export_run", "export_trajectories", "read_pose_covariances"]
