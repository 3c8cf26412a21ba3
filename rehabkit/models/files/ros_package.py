"""A robot description as a ROS description package ships it, made loadable: ``.xacro`` expanded (the ``xacro``
package), every mesh URI resolved — ``package://NAME/...`` the way ROS tools resolve it (the scenario's own
``packages``, then ``ROS_PACKAGE_PATH``, then each ``AMENT_PREFIX_PATH`` prefix's ``share/NAME``, then the running
interpreter's prefixes where pip puts packages: ``sys.prefix`` and cmeel's ``site-packages/cmeel.prefix``),
``file://`` and paths relative to the file — and COLLADA meshes converted to STL, which MuJoCo loads (``trimesh`` with
``pycollada``). The result is one URDF with absolute mesh paths, kept under ``$REHABKIT_CACHE`` by content (written
whole: a temporary name, renamed), from which Pinocchio and MuJoCo both build the robot.
"""

from __future__ import annotations

import hashlib
import os
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from urllib.parse import unquote, urlparse

CONVERTED = (".dae", ".ply")  # mesh formats MuJoCo cannot read, converted to STL


class DescriptionError(ValueError):
    """A description's part that cannot be used: ``uri`` (as written), ``problem`` and the ``fix``; for a package
    not found, ``looked``: the folders it was looked for in (in order); for a file the URI names that is not
    there, ``file``: that path."""

    def __init__(self, uri: str, problem: str, fix: str, looked: Sequence[str] = (), file: Path | None = None):
        self.uri, self.problem, self.fix = uri, problem, fix
        self.looked, self.file = tuple(looked), file
        super().__init__(f"{uri}: {problem}; {fix}")


def cache_dir() -> Path:
    return Path(os.environ.get("REHABKIT_CACHE", Path.home() / ".cache" / "rehabkit")) / "descriptions"


def _is_package(folder: Path, name: str) -> bool:
    if not folder.is_dir():
        return False
    manifest = folder / "package.xml"
    if manifest.is_file():
        found = ET.parse(manifest).getroot().findtext("name")
        return (found or "").strip() == name
    return folder.name == name


def find_package(name: str, packages: Sequence[Path] = ()) -> tuple[Path | None, list[str]]:
    """Package ``name``'s folder, and where it was looked for."""
    looked: list[str] = []
    roots = [*packages, *(Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p)]
    for root in roots:
        looked.append(str(root))
        for folder in (root, root / name):
            if _is_package(folder, name):
                return folder, looked
        if root.is_dir():  # (a workspace's src: the package one level down, under a folder of any name)
            for folder in sorted(root.iterdir()):
                if _is_package(folder / name, name):
                    return folder / name, looked
    ament = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in dict.fromkeys([*ament, *interpreter_prefixes()]):
        looked.append(str(prefix / "share"))
        if (prefix / "share" / name).is_dir():
            return prefix / "share" / name, looked
    return None, looked


def interpreter_prefixes() -> list[Path]:
    """Where pip puts description packages for the running interpreter: its environment's prefix and the base
    interpreter's (``share/NAME``), and cmeel's prefix in every site-packages on its path
    (``site-packages/cmeel.prefix``: example-robot-data, Pinocchio's own) — a venv made with
    ``--system-site-packages`` included — so a pip-installed package needs no variable."""
    import sys

    places = [Path(sys.prefix), Path(sys.base_prefix)]
    places += [Path(p) / "cmeel.prefix" for p in sys.path if p.endswith(("site-packages", "dist-packages"))]
    return [p for p in dict.fromkeys(places) if p.is_dir()]


def resolve_uri(uri: str, base: Path, packages: Sequence[Path] = (), what: str = "mesh") -> Path:
    """A file from its URI (``what``: a description's mesh, or the robot's ``description`` file itself) relative to
    ``base`` (the description's folder, or the scenario's)."""
    parsed = urlparse(uri)
    if parsed.scheme == "package":
        folder, looked = find_package(parsed.netloc, packages)
        if folder is None:
            where = ", ".join(looked) or "nothing: no packages, ROS_PACKAGE_PATH, AMENT_PREFIX_PATH or pip's prefixes"
            raise DescriptionError(uri, f"no package '{parsed.netloc}' found (looked in: {where})",
                                   "name its folder in the robot's packages, or set ROS_PACKAGE_PATH / source the "
                                   "workspace that has it", looked=looked)
        path = folder / unquote(parsed.path).lstrip("/")
    elif parsed.scheme == "file":
        path = Path(unquote(parsed.path))
    elif parsed.scheme:
        raise DescriptionError(uri, f"a '{parsed.scheme}://' URI is not a file here", "use package://, file:// or a "
                               "path relative to the description")
    else:
        path = base / uri
    if not path.is_file():
        fix = "check the package's meshes folder" if what == "mesh" else "check the path after the package's name: " \
            "it is relative to the package's folder (where its package.xml is)"
        raise DescriptionError(uri, f"no such file: {path}", fix, file=path)
    return path.resolve()


def _written(path: Path, data: bytes) -> Path:
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(f".{path.name}.{os.getpid()}.part")
        part.write_bytes(data)
        os.replace(part, path)
    return path


def converted(mesh: Path) -> Path:
    """A COLLADA (or PLY) mesh as an STL MuJoCo loads (its scenes' geometry in the file's units, merged), once per
    content."""
    import trimesh

    digest = hashlib.sha256(mesh.read_bytes()).hexdigest()[:20]
    out = cache_dir() / "meshes" / f"{mesh.stem}-{digest}.stl"
    if out.exists():
        return out
    with warnings.catch_warnings():
        # pycollada 0.9.3 (the newest release) sets arrays' .shape, which NumPy 2.5 deprecates; fixed upstream
        # (pycollada PRs 163 and 164), not yet released: drop this once a newer pycollada is required
        warnings.filterwarnings("ignore", "Setting the shape on a NumPy array", DeprecationWarning, r"collada\.")
        loaded = trimesh.load(str(mesh), force="mesh")
    if loaded.is_empty:
        raise DescriptionError(str(mesh), "the file holds no triangles", "export the mesh with its geometry")
    return _written(out, loaded.export(file_type="stl"))


def prepared(path: Path, packages: Sequence[Path] = (), xacro_args: Mapping[str, str] | None = None) -> Path:
    """The description at ``path`` as one loadable URDF (see the module's doc); a plain URDF whose meshes need
    nothing done is returned as it is."""
    if path.suffix == ".xacro":
        import xacro

        text = xacro.process_file(str(path), mappings=dict(xacro_args or {})).toxml()
    else:
        text = path.read_text()
    root = ET.fromstring(text)
    changed = path.suffix == ".xacro"
    for mesh in root.iter("mesh"):
        uri = mesh.get("filename", "")
        if not uri:
            continue
        file = resolve_uri(uri, path.parent, packages)
        if file.suffix.lower() in CONVERTED:
            file = converted(file)
        if str(file) != uri:
            mesh.set("filename", str(file))
            changed = True
    if not changed:
        return path
    data = ET.tostring(root, encoding="unicode").encode()
    digest = hashlib.sha256(data).hexdigest()[:20]  # (a folder per content: the file keeps its name, for messages)
    return _written(cache_dir() / digest / f"{path.name.removesuffix('.xacro').removesuffix('.urdf')}.urdf", data)


def visual_only(path: Path) -> str | None:
    """What of the (prepared) description at ``path`` only its looks need, which the simulation leaves out, said once
    (None: nothing): MuJoCo's URDF import keeps each link's collision geometry, in its material's colour, and drops
    the visual geometry — a link with a visual and no collision is not drawn, a material's texture not shown."""
    root = ET.parse(path).getroot()
    textured = sorted({m.get("name", "?") for m in root.iter("material") if m.find("texture") is not None})
    unseen = [link.get("name", "?") for link in root.iter("link")
              if link.find("visual") is not None and link.find("collision") is None]
    said = []
    if unseen:
        said.append(f"link(s) {', '.join(unseen)} have a visual and no collision geometry: not drawn")
    if textured:
        said.append(f"the texture of material(s) {', '.join(textured)} is not shown (their colour is)")
    if not said:
        return None
    return (f"{path.name}: MuJoCo simulates and draws each link by its collision geometry; " + "; ".join(said))
