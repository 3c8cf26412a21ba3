"""A session recorded on a robot, read from its ROS bag: moved below the layers, to :mod:`rehabkit.bags.session_bag`
(a plugin reads a bag too, through :mod:`rehabkit.recordings`); re-exported here for the ROS layer's modules."""

from rehabkit.bags.session_bag import (  # noqa: F401
    COMPANIONS,
    FIX,
    GAP_MIN_S,
    GAP_PERIODS,
    SENSORS,
    TOPICS,
    TYPES,
    WRENCH,
    BagError,
    Gap,
    Series,
    SessionBag,
    ShownTarget,
    parse_topics,
    read_session,
    reading_once,
)
