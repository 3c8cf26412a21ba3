"""MuJoCo as rehabkit's simulator: the ``mujoco`` backend plugin, the scene it composes, what sensors read from it.

MuJoCo's own warnings (a deprecated attribute, an attach without a prefix) become Python warnings of the class
:class:`MujocoWarning`, as a library's should: shown once by Python's filters, collected by pytest, and not
appended to a ``MUJOCO_LOG.TXT`` in whatever folder the program was started from.
"""

import warnings

import mujoco


class MujocoWarning(UserWarning):
    """A warning MuJoCo itself raised (its text as MuJoCo said it)."""


def _warn(message: str) -> None:
    warnings.warn(f"MuJoCo: {message}", MujocoWarning, stacklevel=2)


mujoco.set_mju_user_warning(_warn)
