"""``make demo``: compile shapes; mesh, render and size a zoo model; scan it at a random
pose with the synthetic sensor and recover its pose and shape.

Run with ``python -m csdf.demo [OUTPUT_DIR]`` (default ``demo_output``).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import csdf


def csg_example() -> csdf.Shape:
    """The CSG example of the benchmarks: sphere(1) & box(1.5) minus three cylinders."""
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def _row(counts: dict) -> str:
    return "/".join(str(counts[k]) for k in ("add", "mul", "div", "call", "branch"))


def compile_table() -> None:
    from csdf import zoo

    shapes = {
        "sphere": csdf.sphere(1.0),
        "cylinder": csdf.cylinder(0.5, 1.0),
        "cube": csdf.box(1.0),
        "csg example": csg_example(),
        "cross shaft": zoo.load("cross_shaft"),
        "twisted box": csdf.box((1.0, 0.4, 2.0)).twist(1.0),
    }
    head = (f"{'shape':14s} {'contract':8s} {'L':>5s} {'instr':>5s} {'bytes':>6s} {'compact':>7s}"
            f"  {'expanded add/mul/div/call/branch':>32s}  {'primitive level':>16s}")
    print(head)
    print("-" * len(head))
    for name, s in shapes.items():
        prog = csdf.compile(s)
        print(f"{name:14s} {s.exactness:8s} {s.lipschitz:5.2f} {len(prog):5d} {prog.nbytes:6d} "
              f"{prog.compact_nbytes():7d}  {_row(prog.counts('expanded')):>32s}  "
              f"{_row(prog.counts('primitive')):>16s}")
    print("\nPaper Table 1 (add/mul/div/call/branch): Sphere 3/3/0/1/0, Cylinder 3/2/0/1/2, "
          "Cube 3/3/0/1/14.\ncsdf's cylinder and cube are the exact distances (more "
          "instructions, no error at edges and corners).")


def zoo_model(out: Path, name: str = "chair") -> csdf.Shape:
    from csdf import zoo

    shape = zoo.load(name)
    prog = shape.compile()
    src = len(zoo.source(name).encode())
    print(f"\nzoo model {name!r}: {len(prog.params)} parameters "
          f"({', '.join(p.name for p in prog.params)})")
    print(f"  storage: source {src} B, compact call-level {prog.compact_nbytes()} B, "
          f"expanded bytecode {prog.nbytes} B; Table 1 expanded {_row(prog.counts())}, "
          f"primitive {_row(prog.counts('primitive'))}")
    t0 = time.perf_counter()
    m = csdf.mesh(shape, resolution=160, method="dc", progress=False)
    csdf.io.write_mesh(m, out / f"{name}.stl")
    print(f"  mesh: {len(m.faces):,} triangles, watertight={m.is_watertight}, "
          f"{time.perf_counter() - t0:.2f} s -> {out / f'{name}.stl'}")
    cam = csdf.Camera.look_at(eye=(1.6, -2.0, 1.5), target=(0, 0, 0.45), fov=35,
                              width=640, height=480)
    t0 = time.perf_counter()
    img = csdf.render(shape, cam, shadows=True, ao=True)
    img.save(out / f"{name}.png")
    print(f"  render 640x480: {time.perf_counter() - t0:.2f} s -> {out / f'{name}.png'}")
    return shape


def scan_and_fit(shape: csdf.Shape, seed: int = 7) -> None:
    from csdf.fit.lie import rotation_angle

    rng = np.random.default_rng(seed)
    truth = {"seat_width": 0.52, "back_height": 0.5}
    # upright, turned about z, somewhere near the origin
    pose = csdf.Pose.from_rotvec((0.0, 0.0, rng.uniform(-1.0, 1.0)),
                                 (rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 0.0))
    cam = csdf.Camera.look_at(eye=(0.4, -2.2, 1.5), target=(0, 0, 0.5), fov=45,
                              width=640, height=480)
    pts, _ = csdf.scan(shape, cam, noise=0.002, outliers=0.05, seed=seed, object_pose=pose,
                       params=truth)
    world = cam.camera_to_world(pts)
    print(f"\nsynthetic scan of a chair at a random pose: {len(pts):,} points, "
          "noise 2 mm, 5% outliers")
    # a coarse detection: 10 deg and about 6 cm off
    turn = csdf.Pose.from_rotvec((0.0, 0.0, 0.17)).rotation
    init = csdf.Pose(turn @ pose.rotation, pose.translation + np.array([0.05, -0.03, 0.0]))
    names = list(truth)
    # a single view: the sensor position lets the fit tell front faces from back faces
    kw = dict(init=init, estimate=("pose", "params"), params=names, viewpoint=cam.position)
    csdf.fit(shape, world[:200], **kw)  # JIT
    t0 = time.perf_counter()
    res = csdf.fit(shape, world, **kw)
    dt = time.perf_counter() - t0
    print(f"  recovered in {dt * 1e3:.0f} ms: rotation error "
          f"{np.rad2deg(rotation_angle(res.rotation, pose.rotation)):.2f} deg, translation "
          f"error {np.linalg.norm(res.translation - pose.translation) * 1e3:.1f} mm, "
          f"rmse {res.rmse * 1e3:.2f} mm, "
          f"inliers {res.inlier_fraction:.0%}")
    for k, v in truth.items():
        print(f"  {k:12s} true {v:.4f}  recovered {res.params[k]:.4f}")


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "demo_output")
    out.mkdir(parents=True, exist_ok=True)
    print("csdf", csdf.__version__, "\n")
    compile_table()
    chair = zoo_model(out)
    scan_and_fit(chair)


if __name__ == "__main__":
    main()
