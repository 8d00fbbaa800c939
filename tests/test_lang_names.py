"""Names in the .csdf language: model names shadow built-in function names lexically
(the built-in stays reachable where it is not shadowed; keywords stay reserved), the
printer round-trips shapes whose parameter names equal built-ins, and an unclosed
bracket is reported where it was opened."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf import expr as E

PTS = np.random.default_rng(7).uniform(-1.5, 1.5, (300, 3))


def _same(a: csdf.Shape, b: csdf.Shape) -> None:
    assert a.compile().to_bytes() == b.compile().to_bytes()


def _err(text: str) -> csdf.ModelError:
    with pytest.raises(csdf.ModelError) as e:
        csdf.loads(text, file="model.csdf")
    return e.value


# ------------------------------------------------------------------ shadowing
def test_let_may_use_the_name_of_a_primitive():
    s = csdf.loads("let slab = box((1, 1, 0.1))\nlet link = sphere(0.2)\n"
                   "export slab | link.translate((0, 0, 0.5))\n")
    _same(s, csdf.box((1, 1, 0.1)) | csdf.sphere(0.2).translate((0, 0, 0.5)))


def test_param_and_def_may_use_builtin_names():
    s = csdf.loads("param sqrt = 0.5 in [0.1, 1]\ndef box(r) = sphere(r)\nexport box(sqrt)\n")
    assert [p.name for p in s.params] == ["sqrt"]
    _same(s, csdf.sphere(csdf.param("sqrt", 0.5, 0.1, 1)))


def test_a_constant_may_be_shadowed():
    s = csdf.loads("let pi = 0.25\nexport sphere(pi)\n")
    _same(s, csdf.sphere(0.25))


def test_builtin_is_reachable_before_the_binding_that_shadows_it():
    s = csdf.loads("let a = slab(0.1)\nlet slab = a.translate((0, 0, 1))\nexport slab\n")
    _same(s, csdf.slab(0.1).translate((0, 0, 1)))


def test_a_def_body_sees_the_builtin_it_was_written_against():
    # `plate` is defined before `slab` is shadowed, so its body calls the primitive
    text = "def plate(t) = slab(t)\nlet slab = 0.2\nexport plate(slab)\n"
    _same(csdf.loads(text), csdf.slab(0.2))


def test_a_def_may_wrap_the_builtin_of_its_own_name():
    text = "def box(s) = box((s, s, s)).translate((0, 0, s))\nexport box(0.5)\n"
    _same(csdf.loads(text), csdf.box((0.5, 0.5, 0.5)).translate((0, 0, 0.5)))


def test_an_argument_shadows_only_inside_its_def():
    text = ("def place(sphere) = sphere.translate((1, 0, 0))\n"
            "export place(box(1)) | sphere(0.5)\n")
    _same(csdf.loads(text), csdf.box(1).translate((1, 0, 0)) | csdf.sphere(0.5))


def test_function_bodies_are_lexically_scoped():
    # g's body cannot see f's argument `a` (it could with dynamic scope)
    e = _err("def g() = sphere(a)\ndef f(a) = g()\nexport f(1)\n")
    assert "unknown name 'a'" in e.message and (e.line, e.column) == (1, 18)


def test_functions_may_still_be_written_in_any_order():
    text = "def f(r) = g(r).translate((0, 0, r))\ndef g(r) = sphere(r)\nexport f(0.5)\n"
    _same(csdf.loads(text), csdf.sphere(0.5).translate((0, 0, 0.5)))


def test_calling_a_shadowing_value_says_what_hides_the_builtin():
    e = _err("let box = 1\nexport box(1)\n")
    assert (e.line, e.column) == (2, 8)
    assert "'box' is a number, not a function" in e.message
    assert "line 1" in e.hint and "built-in" in e.hint


@pytest.mark.parametrize("kw", ["param", "let", "def", "export", "in"])
def test_keywords_stay_reserved(kw):
    e = _err(f"let {kw} = 1\nexport sphere(1)\n")
    assert "keyword" in e.message or "unexpected" in e.message


def test_names_are_still_defined_once():
    e = _err("let slab = 1\nlet slab = 2\nexport sphere(slab)\n")
    assert "already defined" in e.message and e.line == 2


# ------------------------------------------------------------------ printer round trip
def test_dumps_round_trips_params_named_like_builtins():
    box = csdf.param("box", 0.5, 0.1, 1.0)
    sq = csdf.param("sqrt", 0.3, 0.0, 2.0)
    inf = csdf.param("inf", 1.0)
    half = csdf.param("zz", 0.2, 0.0, np.inf)  # its range prints `inf`
    shape = csdf.union(csdf.box((box, box, box)),
                       csdf.sphere(E.sqrt(sq) * inf + half).translate((0, 0, 1)), k=0.05)
    text = csdf.dumps(shape)
    back = csdf.loads(text)
    _same(back, shape)
    np.testing.assert_allclose(back(PTS, box=0.7, inf=2.0), shape(PTS, box=0.7, inf=2.0))
    assert [p.name for p in back.params] == ["box", "inf", "sqrt", "zz"]
    assert back.params[3].hi == np.inf


def test_dumps_round_trips_a_loaded_model_that_shadows_builtins():
    text = ("def plate(t) = slab(t).translate((0, 0, t))\n"
            "param slab = 0.1 in [0.05, 0.2]\nparam link = 0.3 in [0.1, 0.5]\n"
            "let ring = torus(link, slab / 2)\n"
            "export plate(slab) | ring | ring.translate((0, 0, 1))\n")
    shape = csdf.loads(text)
    back = csdf.loads(csdf.dumps(shape))
    _same(back, shape)


def test_dumps_let_names_avoid_parameter_names():
    s1 = csdf.param("s1", 0.5)
    shared = csdf.sphere(s1)
    shape = shared | shared.translate((1, 0, 0))
    _same(csdf.loads(csdf.dumps(shape)), shape)


# ------------------------------------------------------------------ unclosed brackets
@pytest.mark.parametrize("text,line,col,msg", [
    ("param r = 1\nexport sphere(r", 2, 14, "'(' was never closed"),
    ("param r = 1\nlet a = union(sphere(r),\n  box(1)\nexport a\n", 2, 14,
     "'(' was never closed"),
    ("let v = [(0, 0), (1, 0)\nexport extrude(polygon(v), 1)\n", 1, 9, "'[' was never closed"),
    ("export sphere((1\n", 1, 15, "'(' was never closed"),
    ("export box((1, 2, 3]) # ( in a comment\n", 1, 20,
     "closing bracket ']' does not match opening bracket '('"),
])
def test_unclosed_bracket_is_reported_where_it_was_opened(text, line, col, msg):
    e = _err(text)
    assert (e.line, e.column) == (line, col), str(e)
    assert msg in e.message, str(e)
    assert str(e).startswith(f"model.csdf:{line}:{col}: {msg}")


def test_brackets_in_comments_do_not_count():
    e = _err("# (\nexport sphere(1 # (\n")
    assert (e.line, e.column) == (2, 14) and "'(' was never closed" in e.message


def test_other_syntax_errors_are_unchanged():
    e = _err("export sphere(r +)\n")
    assert (e.line, e.column) == (1, 18) and "unexpected ')'" in e.message
    e = _err("export sphere(1))\n")
    assert (e.line, e.column) == (1, 17) and "unexpected ')'" in e.message


def test_documented_examples():
    import re
    from pathlib import Path

    doc = (Path(__file__).parent.parent / "docs" / "language.md").read_text()
    names = doc.split("## Names and scope", 1)[1]
    block = re.findall(r"```\n(.*?)```", names, re.S)[0]
    shape = csdf.loads(block)
    ref = csdf.slab(csdf.param("slab", 0.02, 0.01, 0.05)) | csdf.box(
        (0.1, 0.1, 0.1)).translate((0, 0, 0.2))
    _same(shape, ref)
    shown = re.search(r"```\n(model\.csdf:2:14: .*?)```", doc, re.S).group(1)
    line2 = shown.splitlines()[1].strip()
    text = f"param r = 0.5\n{line2}\nexport s\n"
    assert str(_err(text)).strip() == shown.strip()


def test_dumps_refuses_a_parameter_named_like_a_keyword():
    with pytest.raises(csdf.CsdfError, match="keyword"):
        csdf.dumps(csdf.sphere(csdf.param("let", 0.5)))


@pytest.mark.parametrize("name", sorted(n for n, e in csdf.REGISTRY.items()
                                        if e.kind in ("primitive3d", "primitive2d")))
def test_dumps_round_trips_a_parameter_named_like_any_primitive(name):
    entry = csdf.REGISTRY[name]
    p = csdf.param(name, 0.25, 0.1, 0.5)
    prim = entry.fn() if entry.kind == "primitive3d" else csdf.extrude(entry.fn(), 1)
    shape = csdf.union(prim, csdf.sphere(p).translate((0, 0, E.sqrt(p))), k=0.01)
    back = csdf.loads(csdf.dumps(shape))
    _same(back, shape)
