"""ROS bags (ROS 1 ``.bag``, ROS 2 folder, ``.mcap`` or ``.db3``) to the recording layout.

Modules
-------
reader
    Opening a bag, listing and selecting its topics, message stamps.
images
    ``sensor_msgs/Image`` and ``CompressedImage`` to grey images.
transforms
    Fixed transforms (``/tf_static``, ``static_transform_publisher`` lines) and GPS fixes in local ENU.
camera_info
    ``sensor_msgs/CameraInfo`` to ``cam0/sensor.yaml`` entries.
streams
    Sorting, de-duplicating and writing the rows of one stream.
summary
    What an import wrote.
importer
    :func:`import_bag`, one pass over the bag writing every stream.
"""

from fusion_vo.recording.rosbag.camera_info import camera_info_yaml, pick_camera_info
from fusion_vo.recording.rosbag.images import (
    IMAGE_ENCODINGS,
    UnsupportedImage,
    compressed_to_grey,
    image_to_grey,
)
from fusion_vo.recording.rosbag.importer import import_bag
from fusion_vo.recording.rosbag.reader import (
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
from fusion_vo.recording.gps import geodetic_to_enu
from fusion_vo.recording.rosbag.summary import ImportSummary, StreamSummary
from fusion_vo.recording.rosbag.transforms import (
    StaticTransform,
    chain_transform,
    parse_static_tf,
    quat_to_matrix,
    ypr_to_matrix,
)

__all__ = [
    "CAMERA_INFO", "COMPRESSED_IMAGE", "IMAGE", "IMAGE_ENCODINGS", "IMU", "NAV_SAT_FIX", "ODOMETRY",
    "STREAM_TYPES", "TF_MESSAGE",
    "BagTopic", "ImportSummary", "StaticTransform", "StreamSummary", "UnsupportedImage",
    "camera_info_yaml", "chain_transform", "compressed_to_grey", "geodetic_to_enu", "image_to_grey",
    "import_bag", "list_topics", "open_reader", "parse_static_tf", "pick_camera_info", "quat_to_matrix",
    "select_topics", "ypr_to_matrix",
]
