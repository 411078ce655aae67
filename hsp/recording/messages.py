"""ROS 2 message definitions (``ros2msg`` schema text, dependencies appended as rosbag2
does) for the topics hsp writes, and the topic names."""

from __future__ import annotations

SEPARATOR = "=" * 80 + "\n"

GROUND_TRUTH_POSES = "/hsp/ground_truth/poses"
GROUND_TRUTH_SUBTASK = "/hsp/ground_truth/subtask"
GROUND_TRUTH_PREFIX = "/hsp/ground_truth/"

# realsense-ros >= 4.55 names (before: without the second "camera/").
CAMERA_NS = "/camera/camera"
COLOR_IMAGE = f"{CAMERA_NS}/color/image_raw"
COLOR_INFO = f"{CAMERA_NS}/color/camera_info"
DEPTH_IMAGE = f"{CAMERA_NS}/aligned_depth_to_color/image_raw"
DEPTH_INFO = f"{CAMERA_NS}/aligned_depth_to_color/camera_info"
TF_STATIC = "/tf_static"
COLOR_FRAME = "camera_color_optical_frame"

_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_TRANSFORM = "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
_TRANSFORM_STAMPED = (
    "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"
)
_POSE = "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"


def _msgdef(main: str, *deps: str) -> str:
    return main + "".join(SEPARATOR + d for d in deps)


TF_MESSAGE = (
    "tf2_msgs/msg/TFMessage",
    _msgdef("geometry_msgs/TransformStamped[] transforms\n", _TRANSFORM_STAMPED, _HEADER, _TIME, _TRANSFORM, _VECTOR3, _QUATERNION),
)

IMAGE = (
    "sensor_msgs/msg/Image",
    _msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        _HEADER, _TIME,
    ),
)

_ROI = "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
CAMERA_INFO = (
    "sensor_msgs/msg/CameraInfo",
    _msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\n"
        "float64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
        _HEADER, _TIME, _ROI,
    ),
)

SUBTASK = (
    "hsp_msgs/msg/Subtask",
    _msgdef(
        "# The demonstrator's own sub-task annotation (ground truth): tool o+, target o*,\n"
        "# way-point w (tool pose in the target frame) and whether the gripper is closed.\n"
        "std_msgs/Header header\nint32 tool\nint32 target\nstring tool_name\nstring target_name\n"
        "int32 waypoint_index\ngeometry_msgs/Pose waypoint\nbool grasped\n",
        _HEADER, _TIME, _POSE, _POINT, _QUATERNION,
    ),
)
