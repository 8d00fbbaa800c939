"""csdf.distributed on a Dask LocalCluster with worker processes: the mesh equals the
one-machine mesh, evaluation equals in-process evaluation, fit_many equals a loop of
csdf.fit, and each worker makes a job's field (and loads its kernels) once."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

import csdf
from csdf.errors import CsdfError
from csdf.mesh.parts import canonical

distributed = pytest.importorskip("distributed") if not os.environ.get(
    "CSDF_REQUIRE_TOOLS") else __import__("distributed")
import csdf.distributed as cd  # noqa: E402

CSG = (csdf.sphere(1.0) & csdf.box(1.5)) - csdf.cylinder(0.5, 3)
PARAM = csdf.sphere(csdf.param("r", 0.8, lo=0.2, hi=2.0)) | csdf.box(
    (csdf.param("w", 1.2, lo=0.1, hi=3.0), 0.3, 0.3))


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _same(a, b):
    ca, cb = canonical(a.vertices, a.faces), canonical(b.vertices, b.faces)
    return ca[0].shape == cb[0].shape and np.array_equal(ca[0], cb[0]) and \
        np.array_equal(ca[1], cb[1])


def _blocks_left() -> list[str]:
    folder = cd.api.SHARED_FOLDER
    return [n for n in os.listdir(folder) if n.startswith("csdf-")] if folder else []


@pytest.mark.parametrize("assembly", ["workers", "client", "records"])
def test_mesh_equals_one_machine_mesh(client, monkeypatch, assembly):
    # workers: they write the mesh into a shared memory block (they run on this
    # machine); client: the parts come back and are stitched here (workers elsewhere);
    # records: the block has no room in the shared folder, the workers send their
    # records and the client writes them
    if assembly == "client":
        monkeypatch.setattr(cd.api, "SHARED_FOLDER", None)
    if assembly == "records":
        monkeypatch.setattr(cd.api, "_room", lambda folder, layout: False)
    left = _blocks_left()
    whole = csdf.mesh(CSG, resolution=160, progress=False, check_thin=False)
    before = client.run(cd.worker_stats)
    d = cd.mesh(CSG, resolution=160, client=client, super_brick=32, progress=False)
    meta = d.metadata["csdf"]
    assert meta["tasks"] > 20 and meta["super_brick"] == 32
    assert meta["assembled"] == {"workers": "shared", "client": "parts",
                                 "records": "records"}[assembly]
    assert _same(whole, d)
    assert d.is_watertight and d.is_winding_consistent
    assert _blocks_left() == left  # (the block's file is gone; its memory is the mesh's)
    after = client.run(cd.worker_stats)
    made = sum(after[w]["fields_made"] - before[w]["fields_made"] for w in after)
    ran = sum(after[w]["tasks"] - before[w]["tasks"] for w in after)
    assert ran == meta["tasks"]
    assert made <= len(after)  # one field (one kernel load) per worker, not per task


def test_mesh_with_params_and_default_plan(client):
    params = {"r": 0.9, "w": 2.2}
    whole = csdf.mesh(PARAM, resolution=200, params=params, progress=False,
                      check_thin=False)
    d = cd.mesh(PARAM, resolution=200, params=params, client=client, progress=False)
    assert 1 < d.metadata["csdf"]["tasks"] <= 96
    assert _same(whole, d)


@pytest.mark.parametrize("suffix", [".ply", ".stl"])
def test_mesh_written_by_the_workers(client, tmp_path, suffix):
    whole = csdf.mesh(CSG, resolution=120, progress=False, check_thin=False)
    d = cd.mesh(CSG, resolution=120, client=client, progress=False, max_tasks=20)
    res = cd.mesh(CSG, resolution=120, client=client, progress=False, max_tasks=20,
                  out=tmp_path / f"m{suffix}")
    assert isinstance(res, cd.MeshFile) and res.tasks > 4
    assert (res.vertices, res.faces) == (len(whole.vertices), len(whole.faces))
    assert [p.name for p in tmp_path.iterdir()] == [f"m{suffix}"]  # no temporaries
    back = trimesh.load(res.path, process=False)
    if suffix == ".ply":  # the workers' file is the in-memory mesh, bit for bit
        assert _same(d, back) and _same(whole, back)
        assert back.is_watertight and back.is_winding_consistent
    else:  # float32 corners, one triple per face
        assert len(back.faces) == len(whole.faces)
        assert np.allclose(np.sort(back.triangles.reshape(-1, 9), axis=0),
                           np.sort(whole.triangles.reshape(-1, 9), axis=0), atol=1e-6)
        assert trimesh.load(res.path).is_watertight  # (merged on load)
    again = cd.mesh(CSG, resolution=120, client=client, progress=False, super_brick=32,
                    out=tmp_path / f"m{suffix}")  # (one cube size, many parts)
    assert again.tasks > 20 and (again.vertices, again.faces) == (res.vertices, res.faces)


def test_default_plan(client):
    fld = csdf.as_field(CSG)
    d = cd.mesh(CSG, resolution=256, client=client, progress=False)
    meta = d.metadata["csdf"]
    assert 1 < meta["tasks"] <= cd.TASKS_PER_THREAD * 2  # (two workers)
    assert meta["super_brick"] <= 512
    assert _same(csdf.mesh(fld, resolution=256, progress=False, check_thin=False), d)
    assert d.is_watertight


def test_connect_sets_the_workers_environment(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")  # (as Dask's own clusters leave)
    monkeypatch.delenv("CSDF_THREADS", raising=False)
    c = cd.connect(workers=2)
    try:
        env = c.run(lambda: (os.environ.get("CSDF_THREADS"),
                             os.environ.get("MALLOC_TRIM_THRESHOLD_")))
    finally:
        cd.disconnect(c)
    share = str(max(1, len(os.sched_getaffinity(0)) // 2))
    assert list(env.values()) == [(share, None)] * 2
    assert os.environ["MALLOC_TRIM_THRESHOLD_"] == "65536"  # this process's, as it was
    assert "CSDF_THREADS" not in os.environ


def test_mesh_bad_arguments(client, tmp_path):
    with pytest.raises(CsdfError, match="marching-cubes"):
        cd.mesh(CSG, method="dc", client=client)
    with pytest.raises(CsdfError, match="resolution"):
        cd.mesh(CSG, resolution=1, client=client)
    with pytest.raises(CsdfError, match=r"\.ply or \.stl"):
        cd.mesh(CSG, resolution=64, client=client, out=tmp_path / "m.glb")
    with pytest.raises(CsdfError, match="range"):
        cd.mesh(PARAM, resolution=64, params={"r": 99.0}, client=client)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("what", ["value", "gradient", "param_jacobian"])
def test_evaluate_equals_in_process(client, what):
    import dask.array as da

    pts = np.random.default_rng(1).uniform(-1.5, 1.5, size=(20_000, 3))
    fld = csdf.as_field(PARAM, {"r": 1.1})
    ref = getattr(fld, what)(pts)
    got = cd.evaluate(PARAM, da.from_array(pts, chunks=(3000, 1)), {"r": 1.1},
                      what=what).compute()
    assert got.shape == ref.shape
    assert np.array_equal(got, ref)
    with pytest.raises(CsdfError, match="shape"):
        cd.evaluate(PARAM, np.zeros((5, 2)))
    with pytest.raises(CsdfError, match="what"):
        cd.evaluate(PARAM, pts, what="hessian")


def test_sample_surface_and_volume(client):
    p, n = cd.sample_surface(CSG, 25_000, seed=3, chunk=10_000)
    assert p.shape == (25_000, 3) and p.chunks[0] == (10_000, 10_000, 5_000)
    p, n = client.compute([p, n], sync=True)
    fld = csdf.as_field(CSG)
    assert np.abs(fld.value(p)).max() < 1e-9
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    again = cd.sample_surface(CSG, 25_000, seed=3, chunk=10_000)[0].compute()
    assert np.array_equal(p, again)  # the same seed and chunk: the same points
    q, d = cd.sample_volume(CSG, 8_000, seed=4, chunk=3_000)
    q, d = client.compute([q, d], sync=True)
    assert np.array_equal(d, fld.value(q))
    with pytest.raises(CsdfError, match="Generator"):
        cd.sample_surface(CSG, 10, seed=np.random.default_rng(0))


def test_fit_many_equals_a_loop(client, tmp_path):
    shape = csdf.box((1.0, 0.6, 0.4))
    rng = np.random.default_rng(0)
    clouds = []
    for i in range(5):
        p, _ = csdf.sample_surface(shape, 400, seed=i)
        clouds.append(p + rng.normal(size=3) * 0.05)
    path = tmp_path / "c.ply"
    csdf.io.write_points(path, clouds[0])
    inputs = clouds + [np.zeros((5, 2)), str(tmp_path / "missing.ply"), str(path)]
    res = cd.fit_many(shape, inputs, client=client, estimate="pose")
    assert len(res) == len(inputs)
    for r, cl in zip(res[:5], clouds):
        ref = csdf.fit(shape, cl, estimate="pose")
        assert np.array_equal(r.rotation, ref.rotation)
        assert np.array_equal(r.translation, ref.translation)
    assert isinstance(res[5], cd.FitFailure) and "(N, 3)" in res[5].message
    assert isinstance(res[6], cd.FitFailure) and "missing.ply" in res[6].message
    assert not res[5].success
    assert np.array_equal(res[7].translation, res[0].translation)  # read by a worker
    with pytest.raises(CsdfError, match="no argument"):
        cd.fit_many(shape, clouds, client=client, estimat="pose")


def test_cli_workers(tmp_path):
    model = tmp_path / "box.csdf"
    model.write_text("export box((1, 0.6, 0.4))\n")
    from csdf.cli import app

    runner = CliRunner()
    r = runner.invoke(app, ["mesh", str(model), "-o", str(tmp_path / "b.ply"), "-r", "96",
                            "--workers", "1", "--super-brick", "32", "-q"])
    assert r.exit_code == 0, r.output
    assert "tasks" in r.output
    m = trimesh.load(tmp_path / "b.ply", process=False)
    assert _same(csdf.mesh(csdf.box((1, 0.6, 0.4)), resolution=96, progress=False,
                           check_thin=False), m)
    scans = tmp_path / "scans"
    scans.mkdir()
    for i in range(2):
        p, n = csdf.sample_surface(csdf.box((1, 0.6, 0.4)), 300, seed=i)
        csdf.io.write_points(scans / f"s{i}.ply", p + 0.02 * i, n)
    (scans / "broken.ply").write_text("nope")
    r = runner.invoke(app, ["fit", str(model), str(scans), "-o", str(tmp_path / "f.json")])
    assert r.exit_code == 0, r.output
    fits = json.loads((tmp_path / "f.json").read_text())["fits"]
    assert [f["scan"].rsplit("/", 1)[1] for f in fits] == ["broken.ply", "s0.ply", "s1.ply"]
    assert "error" in fits[0] and fits[1]["success"] and fits[2]["success"]
    r = runner.invoke(app, ["mesh", str(model), "-o", str(tmp_path / "c.ply"),
                            "--workers", "1", "--scheduler", "tcp://127.0.0.1:1"])
    assert r.exit_code != 0 and "not both" in r.output


def test_a_shared_block_whose_view_outlives_its_task_is_not_an_error(tmp_path):
    """``write_part`` unmaps its block after its views are gone; a view that something
    else still holds (CI once failed on ``BufferError: cannot close exported pointers
    exist``) leaves the unmapping to that view, and the records stay written."""
    import mmap

    from csdf.distributed.tasks import _close_map

    path = tmp_path / "block"
    path.write_bytes(bytes(64))
    with open(path, "r+b") as f:
        block = mmap.mmap(f.fileno(), 0, flags=mmap.MAP_SHARED)
    view = np.frombuffer(block, dtype=np.float64, count=4)
    view[:] = [1.0, 2.0, 3.0, 4.0]
    _close_map(block)  # the view still exports the buffer: no error
    assert not block.closed
    del view
    _close_map(block)
    assert block.closed
    assert np.frombuffer(path.read_bytes(), dtype=np.float64)[:4].tolist() == [1, 2, 3, 4]
