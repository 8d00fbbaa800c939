"""Robot descriptions shipped by PyPI packages: ``example-robot-data`` (the
``bench-plan`` extra) holds URDFs and SRDFs of common arms, among them the Franka Emika
Panda with a collision model of primitives (``panda_collision.urdf``: 13 capsules, each a
cylinder with a sphere on each end).
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

from ..errors import CsdfError
from .robot import Robot

__all__ = ["example_robot", "example_robot_files"]


def example_robot_files(name: str, meshes: bool = False) -> tuple[Path, Path | None]:
    """``(urdf, srdf or None)`` of robot ``name`` in example-robot-data: its
    ``{name}_collision.urdf`` where there is one (primitive collision geometry) unless
    ``meshes``, else ``{name}.urdf`` (usually mesh collision geometry), and
    ``srdf/{name}.srdf``.

    Raises:
        CsdfError: the package is not installed, or has no such robot.
    """
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise CsdfError("example robots need the example-robot-data package: "
                        "pip install 'csdf[bench-plan]'") from None
    found: dict[str, Path] = {}
    prefix = f"robots/{name}_description/"
    for f in dist.files or ():
        s = str(f).replace("\\", "/")
        if prefix in s:
            found[s.split(prefix, 1)[1]] = Path(str(dist.locate_file(f)))
    urdf = None if meshes else found.get(f"urdf/{name}_collision.urdf")
    urdf = urdf or found.get(f"urdf/{name}.urdf")
    if urdf is None:
        names = sorted({str(f).split("robots/", 1)[1].split("_description")[0]
                        for f in dist.files or () if "_description/urdf/" in str(f)})
        raise CsdfError(f"example-robot-data has no robot {name!r} (it has: "
                        f"{', '.join(names)})")
    return urdf, found.get(f"srdf/{name}.srdf")


def example_robot(name: str = "panda", lock: dict[str, float] | None = None,
                  meshes: bool = False, mesh_spacing: float | None = None) -> Robot:
    """Robot ``name`` of example-robot-data, read with its SRDF's disabled collision
    pairs (:meth:`Robot.from_urdf`; ``lock`` holds joints still, e.g. the Panda's
    fingers: ``{'panda_finger_joint1': 0.04}``; ``meshes`` reads the description with
    mesh collision geometry, each mesh as spheres holding it)."""
    urdf, srdf = example_robot_files(name, meshes)
    return Robot.from_urdf(urdf, srdf=srdf, lock=lock, mesh_spacing=mesh_spacing)
