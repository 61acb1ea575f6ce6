"""Reading the meshcat scenes kinfw draws: a window that records the commands, and the
objects and transforms they set (shared by the view tests)."""

import numpy as np

KINFW = "/meshcat/kinfw"


class RecordingWindow:
    """The smallest meshcat window: keeps every command as ``command.lower()``."""

    def __init__(self):
        self.commands = []

    def send(self, command):
        self.commands.append(command.lower())

    def get_scene(self):
        raise AssertionError("the scene tests do not ask for HTML")


def scene_objects(commands):
    """{path: lowered object} of every set_object."""
    return {c["path"]: c["object"] for c in commands if c["type"] == "set_object"}


def scene_transforms(commands):
    """{path: 4x4 matrix} of the last set_transform of every path (meshcat sends
    column-major lists)."""
    return {
        c["path"]: np.array(c["matrix"], float).reshape(4, 4).T
        for c in commands
        if c["type"] == "set_transform"
    }
