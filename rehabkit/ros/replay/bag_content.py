"""What a bag's messages hold, checked as they are read: moved below the layers, to :mod:`rehabkit.bags.bag_content`;
re-exported here for the ROS layer's modules."""

from rehabkit.bags.bag_content import (  # noqa: F401
    REPLAY_NEEDS,
    BagError,
    Remark,
    Where,
    first_bad,
    not_finite,
    refuse_rows,
)
