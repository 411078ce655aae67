"""ROS 2 message definitions (``ros2msg`` schema text, dependencies appended as rosbag2
does) for the topics hsp writes, and the topic names."""

from __future__ import annotations

SEPARATOR = "=" * 80 + "\n"

GROUND_TRUTH_POSES = "/hsp/ground_truth/poses"
GROUND_TRUTH_SUBTASK = "/hsp/ground_truth/subtask"
GROUND_TRUTH_PREFIX = "/hsp/ground_truth/"

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
