"""A meshcat scene as one self-contained HTML file, without a server.

:class:`OfflineWindow` records meshcat's commands like a server would (draw into
``meshcat.Visualizer(window=OfflineWindow())``); :func:`write_html` saves a scene as one
HTML file with meshcat's viewer script inlined (no network access), and
:func:`external_urls` lists what a page would fetch. The scene itself is drawn by
:func:`kinfw.view.scene`. meshcat is imported inside the functions.
"""

from __future__ import annotations

import base64
import logging
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from kinfw.files import write_text_atomic

if TYPE_CHECKING:
    import meshcat

logger = logging.getLogger("kinfw.view")

# URLs that a browser never fetches: XML namespaces in meshcat's viewer script.
_NAMESPACE_URLS = ("http://www.w3.org/",)
_URL = re.compile(r"https?://[^\s\"'<>)]*", re.IGNORECASE)


# -- offline window ----------------------------------------------------------------------


class OfflineWindow:
    """A meshcat window without a server: records commands, serves the static HTML.

    ``meshcat.Visualizer(window=OfflineWindow())`` draws into it like into a server:
    the scene tree is kept with the server's rules (a ``set_object`` replaces the node's
    object and properties, ``delete`` removes a subtree), and :meth:`get_scene` returns
    the same self-contained HTML as ``meshcat-server`` (the viewer script inlined).

    Attributes
    ----------
    commands : list of dict
        Every command sent, as ``command.lower()`` (keys ``type``, ``path`` and the
        command's fields), in order.
    """

    def __init__(self) -> None:
        from meshcat.servers.tree import SceneTree

        self.commands: list[dict[str, Any]] = []
        self._tree = SceneTree()

    def send(self, command: Any) -> None:
        """Record one meshcat command (``SetObject``, ``SetTransform``, ...)."""
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        data = command.lower()
        self.commands.append(data)
        kind = data["type"]
        path = [p for p in data.get("path", "").split("/") if p]
        packed = umsgpack.packb(data)
        if kind == "set_object":
            node = find_node(self._tree, path)
            node.object, node.properties = packed, []
        elif kind == "set_transform":
            find_node(self._tree, path).transform = packed
        elif kind == "set_property":
            find_node(self._tree, path).properties.append(packed)
        elif kind == "set_animation":
            find_node(self._tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self._tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self._tree = SceneTree()
        else:
            raise ValueError(
                f"OfflineWindow: cannot record a {kind!r} command without a "
                "browser (get_image needs meshcat.Visualizer())"
            )

    def get_scene(self) -> str:
        """The scene as one self-contained HTML page (what ``meshcat-server`` returns)."""
        import meshcat
        from meshcat.servers.tree import walk

        def command(packed: bytes) -> str:  # as meshcat.servers.zmqserver.create_command
            return (
                '\nfetch("data:application/octet-binary;base64,'
                f'{base64.b64encode(packed).decode("utf-8")}")\n'
                "    .then(res => res.arrayBuffer())\n"
                "    .then(buffer => viewer.handle_command_bytearray("
                "new Uint8Array(buffer)));\n    "
            )

        parts = []
        for node in walk(self._tree):
            if node.object is not None:
                parts.append(command(node.object))
            parts.extend(command(p) for p in node.properties)
            if node.transform is not None:
                parts.append(command(node.transform))
            if node.animation is not None:
                parts.append(command(node.animation))
        viewer = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
        return _HTML.format(mainminjs=viewer.read_text(encoding="utf-8"), commands="".join(parts))

    def open(self) -> OfflineWindow:  # meshcat.Visualizer.open() calls this
        raise RuntimeError("OfflineWindow has no server to open; use write_html()")


_HTML = """<!DOCTYPE html>
<html>
    <head> <meta charset=utf-8> <title>kinfw - MeshCat</title> </head>
    <body>
        <div id="meshcat-pane">
        </div>
        <script>
            {mainminjs}
        </script>
        <script>
            var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
            {commands}
        </script>
         <style>
            body {{margin: 0; }}
            #meshcat-pane {{
                width: 100vw;
                height: 100vh;
                overflow: hidden;
            }}
        </style>
        <script id="embedded-json"></script>
    </body>
</html>
"""


def external_urls(html: str) -> list[str]:
    """The http(s) URLs in ``html`` that a browser could fetch (XML namespace URIs of
    the viewer script are not counted)."""
    return [u for u in _URL.findall(html) if not u.lower().startswith(_NAMESPACE_URLS)]


def write_html(vis: meshcat.Visualizer, path: str | Path) -> Path:
    """Save the scene as one self-contained HTML file and return its path.

    The file holds meshcat's viewer script and the scene's commands; it opens in a
    browser without network access or a server.

    The file is written atomically (:func:`kinfw.files.write_text_atomic`).

    Raises
    ------
    ValueError
        If the HTML would load something from the network (a URL to a CDN).
    """
    html = vis.static_html()
    urls = external_urls(html)
    if urls:
        raise ValueError(
            f"the meshcat HTML refers to the network ({urls[:3]}); it would not be self-contained"
        )
    path = write_text_atomic(path, html)
    logger.debug("wrote %s (%d bytes)", path, path.stat().st_size)
    return path
