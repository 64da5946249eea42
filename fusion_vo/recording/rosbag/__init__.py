"""ROS bags (ROS 1 ``.bag``, ROS 2 folder, ``.mcap`` or ``.db3``) to the recording layout."""

from fusion_vo.recording.rosbag.importer import _camera_info_yaml as camera_info_yaml, _pick_camera_info as pick_camera_info
from fusion_vo.recording.rosbag.importer import (
    IMAGE_ENCODINGS,
    UnsupportedImage,
    compressed_to_grey,
    image_to_grey,
)
from fusion_vo.recording.rosbag.importer import import_bag
from fusion_vo.recording.rosbag.importer import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    IMU,
    NAV_SAT_FIX,
    ODOMETRY,
    STREAM_TYPES,
    TF_MESSAGE,
    BagTopic,
    list_topics,
    open_reader,
    select_topics,
)
from fusion_vo.recording.rosbag.importer import ImportSummary, StreamSummary
from fusion_vo.recording.rosbag.importer import (
    WGS84_A,
    WGS84_E2,
    WGS84_F,
    StaticTransform,
    chain_transform,
    geodetic_to_enu,
    parse_static_tf,
    quat_to_matrix,
    ypr_to_matrix,
)

__all__ = [
    "CAMERA_INFO", "COMPRESSED_IMAGE", "IMAGE", "IMAGE_ENCODINGS", "IMU", "NAV_SAT_FIX", "ODOMETRY",
    "STREAM_TYPES", "TF_MESSAGE", "WGS84_A", "WGS84_E2", "WGS84_F",
    "BagTopic", "ImportSummary", "StaticTransform", "StreamSummary", "UnsupportedImage",
    "camera_info_yaml", "chain_transform", "compressed_to_grey", "geodetic_to_enu", "image_to_grey",
    "import_bag", "list_topics", "open_reader", "parse_static_tf", "pick_camera_info", "quat_to_matrix",
    "select_topics", "ypr_to_matrix",
]
