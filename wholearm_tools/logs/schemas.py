"""Message definitions written into wholearm MCAP files, and the names the reader recognises.

The ROS 2 definitions are the stock ``ros2msg`` texts (as ``ros2 bag record`` stores them, nested
types appended after ``====`` separators) so that any ROS 2 tool, and the stock
``mcap_ros2.decoder.DecoderFactory``, decodes every message.  The JSON profile uses the same
schema names with ``jsonschema`` schemas whose field names are the ROS field names.
"""

from __future__ import annotations

import json
from typing import Any

JOINT_STATE = "sensor_msgs/msg/JointState"
STRING = "std_msgs/msg/String"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
GROUND_TRUTH = "wholearm_msgs/msg/GroundTruth"

JOINT_TOPIC = "/joint_states"
COMMAND_TOPIC = "/joint_commands"
DESCRIPTION_TOPIC = "/robot_description"
TRUTH_TOPIC = "/wholearm/ground_truth"
METADATA_NAME = "wholearm"
FORMAT_VERSION = 1

_SEPARATOR = "\n" + "=" * 80 + "\n"

_HEADER = """# Standard metadata for higher-level stamped data types.
# This is generally used to communicate timestamped data
# in a particular coordinate frame.

# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
"""

_TIME = """# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds component.
# e.g.
# The time -1.7 seconds is represented as {sec: -2, nanosec: 3e8}
# The time 1.7 seconds is represented as {sec: 1, nanosec: 7e8}
uint32 nanosec
"""

_JOINT_STATE = ("# This is a message that holds data to describe the state of a set of torque "
                "controlled joints.\n" """#
# The state of each joint (revolute or prismatic) is defined by:
#  * the position of the joint (rad or m),
#  * the velocity of the joint (rad/s or m/s) and
#  * the effort that is applied in the joint (Nm or N).
#
# Each joint is uniquely identified by its name
# The header specifies the time at which the joint states were recorded. All the joint states
# in one message have to be recorded at the same time.
#
# This message consists of a multiple arrays, one for each part of the joint state.
# The goal is to make each of the fields optional. When e.g. your joints have no
# effort associated with them, you can leave the effort array empty.
#
# All arrays in this message should have the same size, or be empty.
# This is the only way to uniquely associate the joint name with the correct
# states.

std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort
""")

_DEPRECATED = """# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.
"""

_STRING = _DEPRECATED + "\nstring data\n"

_FLOAT64_MULTI_ARRAY = _DEPRECATED + """
# Please look at the MultiArrayLayout message definition for
# documentation on all multiarrays.

MultiArrayLayout  layout        # specification of data layout
float64[]         data          # array of data
"""

_MULTI_ARRAY_LAYOUT = """# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.

# The multiarray declares a generic multi-dimensional array of a
# particular data type.  Dimensions are ordered from outer most
# to inner most.
#
# Accessors should ALWAYS be written in terms of dimension stride
# and specified outer-most dimension first.
#
# multiarray(i,j,k) = data[data_offset + dim_stride[1]*i + dim_stride[2]*j + k]
#
# A standard, 3-channel 640x480 image with interleaved color channels
# would be specified as:
#
# dim[0].label  = "height"
# dim[0].size   = 480
# dim[0].stride = 3*640*480 = 921600  (note dim[0] stride is just size of image)
# dim[1].label  = "width"
# dim[1].size   = 640
# dim[1].stride = 3*640 = 1920
# dim[2].label  = "channel"
# dim[2].size   = 3
# dim[2].stride = 3
#
# The layout above would be written as: data[data_offset + 1920*i + 3*j + k]

MultiArrayDimension[] dim # Array of dimension properties
uint32 data_offset        # padding elements at front of data
"""

_MULTI_ARRAY_DIMENSION = _DEPRECATED + """
string label   # label of given dimension
uint32 size    # size of given dimension (in type units)
uint32 stride  # stride of given dimension
"""

ROS2_DEFINITIONS: dict[str, str] = {
    JOINT_STATE: (_JOINT_STATE + _SEPARATOR + "MSG: std_msgs/Header\n" + _HEADER
                  + _SEPARATOR + "MSG: builtin_interfaces/Time\n" + _TIME),
    STRING: _STRING,
    FLOAT64_MULTI_ARRAY: (_FLOAT64_MULTI_ARRAY
                          + _SEPARATOR + "MSG: std_msgs/MultiArrayLayout\n" + _MULTI_ARRAY_LAYOUT
                          + _SEPARATOR + "MSG: std_msgs/MultiArrayDimension\n"
                          + _MULTI_ARRAY_DIMENSION),
}
ROS2_DEFINITIONS = {name: text.rstrip("\n") for name, text in ROS2_DEFINITIONS.items()}
"""``ros2msg`` schema text by schema name."""

_NUMBERS = {"type": "array", "items": {"type": "number"}}
_TIME_SCHEMA = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nanosec": {"type": "integer", "minimum": 0}},
    "required": ["sec", "nanosec"],
}

JSON_SCHEMAS: dict[str, dict[str, Any]] = {
    JOINT_STATE: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": JOINT_STATE,
        "type": "object",
        "properties": {
            "header": {
                "type": "object",
                "properties": {"stamp": _TIME_SCHEMA, "frame_id": {"type": "string"}},
                "required": ["stamp"],
            },
            "name": {"type": "array", "items": {"type": "string"}},
            "position": _NUMBERS,
            "velocity": _NUMBERS,
            "effort": _NUMBERS,
        },
        "required": ["header", "name", "position"],
    },
    STRING: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": STRING,
        "type": "object",
        "properties": {"data": {"type": "string"}},
        "required": ["data"],
    },
    FLOAT64_MULTI_ARRAY: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": FLOAT64_MULTI_ARRAY,
        "type": "object",
        "properties": {"layout": {"type": "object"}, "data": _NUMBERS},
        "required": ["data"],
    },
    GROUND_TRUTH: {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": GROUND_TRUTH,
        "description": "Ground truth of a simulated wholearm run: environment surfaces and "
                       "per-contact-event truth as columns (index i of every column = contact "
                       "i).  In the ros2 profile this body is the data of a "
                       "std_msgs/msg/String on the same topic.",
        "type": "object",
        "properties": {
            "format_version": {"type": "integer"},
            "surfaces": {"type": "array", "items": {"type": "object"}},
            "contacts": {
                "type": "object",
                "properties": {
                    "t": {**_NUMBERS, "description": "contact time [s] since the log start"},
                    "link": {"type": "array", "items": {"type": "integer"},
                             "description": "0-based link index in contact"},
                    "kind": {"type": "array", "items": {"enum": ["tip", "joint", "body"]}},
                    "point": {"type": "array", "items": {**_NUMBERS, "minItems": 3,
                                                         "maxItems": 3},
                              "description": "contact point on the surface, base frame [m]"},
                    "surface": {"type": "array", "items": {"type": "integer"}},
                    "s": {**_NUMBERS, "description": "fraction along the link axis"},
                    "t_end": {"type": "array", "items": {"type": ["number", "null"]},
                              "description": "release time [s] since the log start"},
                    "force": {"type": "array", "items": {"type": ["number", "null"]},
                              "description": "peak normal force [N]"},
                    "q": {"type": "array",
                          "items": {"type": "array", "items": {"type": ["number", "null"]}},
                          "description": "true configuration where the contact settled [rad]"},
                    "stopped": {"type": "array", "items": {"type": "boolean"},
                                "description": "the contact blocked a commanded motion"},
                    "point_first": {"type": "array", "items": {**_NUMBERS, "minItems": 3,
                                                               "maxItems": 3},
                                    "description": "contact point at first touch [m]"},
                },
                "required": ["t", "link", "kind", "point", "surface", "s"],
            },
            "meta": {"type": "object"},
        },
        "required": ["surfaces", "contacts"],
    },
}
"""``jsonschema`` schema by schema name (the ground-truth body is JSON in both profiles: a
``wholearm_msgs/msg/GroundTruth`` message in the json profile, the data of a
``std_msgs/msg/String`` in the ros2 profile)."""


def json_schema_bytes(name: str) -> bytes:
    """The ``jsonschema`` schema for ``name`` as canonical (sorted, compact) UTF-8 JSON."""
    return json.dumps(JSON_SCHEMAS[name], sort_keys=True, separators=(",", ":")).encode()
