"""The .csdf language: reachability of the whole API, round trips, errors, fuzzing, safety."""

from __future__ import annotations

import os
import random
import string

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import csdf
from csdf.lang.loader import MAX_DEPTH, MAX_FILE_BYTES
from strategies import shapes, shapes_2d

# name -> (model expression, the same shape built in Python)
C = csdf
CASES = {
    "translate": ("box(1).translate((1, 2, 3))", lambda: C.box(1).translate((1, 2, 3))),
    "rotate": ('box(1).rotate(0.5, "x")', lambda: C.box(1).rotate(0.5, "x")),
    "orient": ('cylinder(0.3, 1).orient("x")', lambda: C.cylinder(0.3, 1).orient("x")),
    "transform": ("box(1).transform([[0, -2, 0, 1], [2, 0, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]])",
                  lambda: C.box(1).transform([[0, -2, 0, 1], [2, 0, 0, 0], [0, 0, 2, 0],
                                              [0, 0, 0, 1]])),
    "scale": ("box(1).scale((1, 2, 3)).scale(2)", lambda: C.box(1).scale((1, 2, 3)).scale(2)),
    "mirror": ('sphere(0.3).translate((0.5, 0, 0)).mirror("xy")',
               lambda: C.sphere(0.3).translate((0.5, 0, 0)).mirror("xy")),
    "repeat": ("sphere(0.2).repeat(1.0, count=3)", lambda: C.sphere(0.2).repeat(1.0, count=3)),
    "repeat_mirrored": ("box(0.3).repeat_mirrored((1, 0, 0), count=(3, 1, 1))",
                        lambda: C.box(0.3).repeat_mirrored((1, 0, 0), count=(3, 1, 1))),
    "repeat_polar": ("sphere(0.2).translate((1, 0, 0)).repeat_polar(6)",
                     lambda: C.sphere(0.2).translate((1, 0, 0)).repeat_polar(6)),
    "twist": ("box(1).twist(0.5)", lambda: C.box(1).twist(0.5)),
    "bend": ("box((2, 0.3, 0.3)).bend(0.5)", lambda: C.box((2, 0.3, 0.3)).bend(0.5)),
    "taper": ("box(1).taper(0.2)", lambda: C.box(1).taper(0.2)),
    "elongate": ("sphere(0.3).elongate((0.2, 0, 0))",
                 lambda: C.sphere(0.3).elongate((0.2, 0, 0))),
    "round": ("box(1).round(0.1)", lambda: C.box(1).round(0.1)),
    "offset": ("sphere(1).offset(0.1)", lambda: C.sphere(1).offset(0.1)),
    "shell": ("sphere(1).shell(0.05)", lambda: C.sphere(1).shell(0.05)),
    "bind": ("param r = 1 in [0.5, 2]\nsphere(r).bind(r=0.7) | sphere(r)",
             lambda: C.sphere(C.param("r", 1, 0.5, 2)).bind(r=0.7)
             | C.sphere(C.param("r", 1, 0.5, 2))),
    "rename": ('param param_r = 1 in [0.5, 2]\nsphere(param_r).rename(prefix="a_", suffix="_1")',
               lambda: C.sphere(C.param("param_r", 1, 0.5, 2)).rename(prefix="a_",
                                                                      suffix="_1")),
    "union": ('union(sphere(1), box(1), k=0.2, blend="round")',
              lambda: C.union(C.sphere(1), C.box(1), k=0.2, blend="round")),
    "intersection": ("intersection(sphere(1), box(1), k=0.1)",
                     lambda: C.intersection(C.sphere(1), C.box(1), k=0.1)),
    "difference": ("difference(box(1), sphere(0.6), sphere(0.2))",
                   lambda: C.difference(C.box(1), C.sphere(0.6), C.sphere(0.2))),
    "complement": ("complement(sphere(1))", lambda: C.complement(C.sphere(1))),
    "extrude": ("extrude(circle(1), 2)", lambda: C.extrude(C.circle(1), 2)),
    "revolve": ("revolve(circle(0.2), 1, angle=2)", lambda: C.revolve(C.circle(0.2), 1,
                                                                     angle=2)),
    "color": ("box(1).color((0.2, 0.4, 0.6))", lambda: C.box(1).color((0.2, 0.4, 0.6))),
    "material": ('box(1).material("steel", roughness=0.2)',
                 lambda: C.box(1).material("steel", roughness=0.2)),
    "color_field": ("box(1).color_field((0.5 + 0.5 * x, y * y, 0.3))",
                    lambda: C.box(1).color_field((0.5 + 0.5 * C.x, C.y * C.y, 0.3))),
    "cross_section": ("extrude(cross_section(sphere(1), 0.5), 1)",
                      lambda: C.extrude(C.cross_section(C.sphere(1), 0.5), 1)),
    "normalized": ("field(x * x + y * y + z * z - 1).normalized()",
                   lambda: C.field(C.x * C.x + C.y * C.y + C.z * C.z - 1).normalized()),
    "remap": ("box(1).remap(x = x + 0.3 * y)", lambda: C.box(1).remap(x=C.x + 0.3 * C.y)),
}
for _name, _e in csdf.REGISTRY.items():
    if _e.kind == "primitive3d":
        CASES[_name] = (f"{_name}()", _e.fn)
    elif _e.kind == "primitive2d":
        CASES[_name] = (f"extrude({_name}(), 1)", lambda fn=_e.fn: C.extrude(fn(), 1))


def test_every_api_name_has_a_case():
    assert set(CASES) == set(csdf.REGISTRY)


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_api_name_is_reachable_from_a_model_file(name, tmp_path):
    text, make = CASES[name]
    decls, _, text = text.rpartition("\n")  # a case may declare parameters first
    path = tmp_path / f"{name}.csdf"
    path.write_text(f"# {name}\n{decls}\nexport {text}\n")
    loaded = csdf.load(path)
    assert loaded.compile().to_bytes() == make().compile().to_bytes()


def test_full_language_example():
    text = """
    # a parametric stool
    param height = 0.45 in [0.3, 0.8]
    param leg = 0.03 in [0.02, 0.05]
    let seat = cylinder(0.18, 0.03).translate((0, 0, height))
    def post(h) = cylinder(leg, h).translate((0.12, 0, h / 2))
    let legs = post(height).repeat_polar(3)
    export union(seat, legs, k=0.01) | sphere(sqrt(2) * leg).translate((0, 0, -pi + pi))
    """
    s = csdf.loads(text)
    assert [p.name for p in s.params] == ["height", "leg"]
    h = csdf.param("height", 0.45, 0.3, 0.8)
    leg = csdf.param("leg", 0.03, 0.02, 0.05)
    seat = C.cylinder(0.18, 0.03).translate((0, 0, h))
    legs = C.cylinder(leg, h).translate((0.12, 0, h / 2)).repeat_polar(3)
    ref = C.union(seat, legs, k=0.01) | C.sphere(np.sqrt(2) * leg).translate((0, 0, 0.0))
    pts = np.random.default_rng(0).uniform(-0.5, 0.8, (500, 3))
    np.testing.assert_allclose(s(pts), ref(pts), atol=1e-12)
    assert s(pts, height=0.6) is not None


_SETTINGS = settings(max_examples=150, deadline=None,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@_SETTINGS
@given(shape=shapes())
def test_dumps_loads_round_trip_to_identical_bytecode(shape):
    text = csdf.dumps(shape)
    back = csdf.loads(text)
    assert back.compile().to_bytes() == shape.compile().to_bytes()


@_SETTINGS
@given(shape=shapes_2d())
def test_dumps_loads_round_trip_2d(shape):
    assert csdf.loads(csdf.dumps(shape)).compile().to_bytes() == shape.compile().to_bytes()


def _err(text: str) -> csdf.ModelError:
    with pytest.raises(csdf.ModelError) as e:
        csdf.loads(text, file="m.csdf")
    return e.value


@pytest.mark.parametrize("text,line,col,msg,hint", [
    ("export sphre(1)", 1, 8, "unknown function 'sphre'", "'sphere'"),
    ("let rad = 1\nexport sphere(radd)", 2, 15, "unknown name 'radd'", "'rad'"),
    ("export box(1, 2, 3)", 1, 8, "wrong arguments for box", "box(size=1.0)"),
    ("export box(sise=1)", 1, 8, "wrong arguments for box", "box(size=1.0)"),
    ("export box((1, 2))", 1, 8, "box: size must have 3 components", ""),
    ('export sphere("big")', 1, 8, "sphere: radius must be a number", ""),
    ("param r = 3 in [0, 2]\nexport sphere(r)", 1, 1, "default 3 is outside its range", ""),
    ("export sphere(q)", 1, 15, "unknown name 'q'", ""),
    ("def f(a) = f(a)\nexport f(1)", 1, 12, "calls itself", ""),
    ("def f(a) = g(a)\ndef g(a) = f(a)\nexport f(1)", 2, 12, "calls itself", ""),
    ("let a = sphere(1)\n", 1, 1, "missing 'export'", "export <shape>"),
    ("export sphere(1)\nexport box(1)", 2, 1, "exactly one 'export'", ""),
    ("export sphere(1) + box(1)", 1, 8, "shapes combine with", "| for union"),
    ("export sphere(1).spin(2)", 1, 18, "unknown method 'spin'", ""),
    ("export 1 | sphere(1)", 1, 8, "| combines shapes", ""),
    ("export sphere(1", 1, 14, "'(' was never closed", "add the matching ')'"),
    ("export sphere(1) |", 1, 19, "unexpected end", "expected one of"),
    ("export sphere(1))", 1, 17, "unexpected ')'", ""),
    ("let let = 1", 1, 5, "unexpected 'let'", ""),
    ("let box = 1\nexport box(box)", 2, 8, "'box' is a number, not a function",
     "hides the built-in box()"),
    ("let a = 1\nlet a = 2\nexport sphere(a)", 2, 5, "already defined", ""),
    ("export f(1)\n", 1, 8, "unknown function 'f'", ""),
    ("def f(a, b) = sphere(a)\nexport f(1)", 2, 8, "missing argument", "def f(a, b)"),
    ("export sphere(1).repeat(1, count=10000000)", 1, 8, "count must be in", ""),
    ("export regular_polygon(5000000, 1)", 1, 8, "n must be in", ""),
    ("export sphere(1) $ box(1)", 1, 18, "unexpected character '$'", ""),
])
def test_errors_name_line_column_and_hint(text, line, col, msg, hint):
    e = _err(text)
    assert (e.line, e.column) == (line, col), str(e)
    assert msg in e.message, str(e)
    assert hint in e.hint, str(e)
    assert "m.csdf" in str(e) and "^" in str(e)


def test_limits():
    assert "limit" in _err("#" * (MAX_FILE_BYTES + 1)).message
    deep = "export sphere(" + "-" * (MAX_DEPTH + 5) + "1)"
    assert "nested deeper" in _err(deep).message
    parens = "export sphere(" + "(" * 5000 + "1" + ")" * 5000 + ")"  # collapse: harmless
    assert csdf.loads(parens) is not None
    wide = "let a = sphere(1)\n" + "".join(
        f"let a{i} = a.translate(({i}, 0, 0))\n" for i in range(1200))
    big = wide + "export union(" + ", ".join(f"a{i}" for i in range(1200)) + ")"
    csdf.loads(big)  # a large but legal model loads
    many = "def f(x) = sphere(x)\n" + "".join(f"let v{i} = f({i % 7 + 1})\n" for i in range(60))
    assert csdf.loads(many + "export v1") is not None


INJECTIONS = [
    "export __import__('os').system('echo pwned')",
    "export sphere(1).__class__",
    "export sphere(1).__class__()",
    "export sphere(1).compile()",
    'export "{0.__class__}".format(1)',
    "export eval('sphere(1)')",
    "export exec('import os')",
    "export open('/etc/passwd')",
    "import os\nexport sphere(1)",
    "export (lambda: sphere(1))()",
    "export sphere(1)._fn(None, None)",
    "export [x for x in ()]",
    "export f'{1}'",
    "export sphere(__builtins__)",
    "export globals()",
    "export sphere(1).children",
]


@pytest.mark.parametrize("text", INJECTIONS)
def test_python_injection_is_rejected(text, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(csdf.ModelError):
        csdf.loads(text)
    assert not list(tmp_path.iterdir())


_TOKENS = ["param", "let", "def", "export", "in", "sphere", "box", "union", "(", ")", "[",
           "]", ",", "=", "|", "&", "-", "+", "*", "/", "~", ".", "translate", "x", "1",
           "0.5", "1e308", "1e999", '"x"', "'xy'", "k", "pi", "#", "\n", " ", "r", "f",
           "repeat", "count", "twist", "__class__", "9" * 30, "-1e-308"]


def _random_input(rng: random.Random) -> str:
    if rng.random() < 0.5:
        k = rng.randint(0, 40)
        return "".join(rng.choice(_TOKENS) + rng.choice(["", " "]) for _ in range(k))
    n = rng.randint(0, 80)
    return "".join(rng.choice(string.printable) for _ in range(n))


_SEEDS = [
    "param r = 1 in [0.5, 2]\nexport sphere(r) & box(1.5)",
    "let c = cylinder(0.5, 3)\nexport box(1) - c - c.orient('x')",
    "def post(h) = cylinder(0.05, h)\nexport union(post(1), post(2).translate((1, 0, 0)), k=0.1)",
    "export extrude(polygon([(0, 0), (1, 0), (0.5, 1)]), 0.2).twist(1).repeat(3, count=2)",
]


def _mutate(rng: random.Random, text: str) -> str:
    s = list(text)
    for _ in range(rng.randint(1, 4)):
        op = rng.random()
        i = rng.randrange(len(s) + 1)
        if op < 0.3 and s:
            del s[min(i, len(s) - 1)]
        elif op < 0.6:
            s.insert(i, rng.choice(_TOKENS))
        elif s:
            s[min(i, len(s) - 1)] = rng.choice(string.printable)
    return "".join(s)


def test_fuzzing_only_ever_raises_model_error():
    n = int(os.environ.get("CSDF_FUZZ_EXAMPLES", "3000"))
    rng = random.Random(12345)
    accepted = 0
    for i in range(n):
        text = _random_input(rng) if i % 2 else _mutate(rng, rng.choice(_SEEDS))
        try:
            s = csdf.loads(text)
        except csdf.ModelError:
            continue
        except Exception as exc:  # pragma: no cover - the failure being tested for
            raise AssertionError(f"{type(exc).__name__}: {exc}\ninput: {text!r}") from exc
        accepted += 1
        assert isinstance(s, csdf.Shape)
    assert accepted > 0


def test_documented_example_loads():
    import re
    from pathlib import Path

    doc = (Path(__file__).parent.parent / "docs" / "language.md").read_text()
    block = re.findall(r"```\n(.*?)```", doc, re.S)[0]
    shape = csdf.loads(block)
    assert [p.name for p in shape.params] == ["beam", "radius"]
