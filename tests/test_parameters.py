"""NLP parameters declared by name: pack and unpack are each other's inverse, matrices go
column by column (CasADi's vec), and a wrong or missing name or shape is refused."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from ocp.transcription.parameters import Parameters

DECL = Parameters.of(shape=(2, 1), goal=(5, 1), vias=(5, 3), Pd=(3, 0))


def test_pack_then_unpack_gives_every_value_back_in_its_shape() -> None:
    rng = np.random.default_rng(1)
    values = {"shape": rng.normal(size=2), "goal": rng.normal(size=5),
              "vias": rng.normal(size=(5, 3)), "Pd": np.zeros((3, 0))}
    p = DECL.pack(values)
    assert p.shape == (DECL.size,) == (2 + 5 + 15,)
    parts = DECL.unpack(ca.DM(p))
    for k, v in values.items():
        assert np.array_equal(np.asarray(parts[k]).reshape(np.shape(v) if np.ndim(v) == 2
                                                           else (-1,)), v)
    # the matrix is stored column by column, as CasADi's vec
    assert np.array_equal(p[7:22], values["vias"].ravel(order="F"))
    # symbolic unpacking has the declared shapes
    sym = DECL.unpack(ca.MX.sym("p", DECL.size))
    assert {k: v.shape for k, v in sym.items()} == dict(DECL.fields)


@pytest.mark.parametrize(("values", "words"), [
    ({"shape": [1.0, 2.0], "goal": np.zeros(5), "vias": np.zeros((5, 3))}, "missing ['Pd']"),
    ({"shape": [1.0, 2.0], "goal": np.zeros(5), "vias": np.zeros((5, 3)), "Pd": np.zeros((3, 0)),
      "extra": [1.0]}, "unknown ['extra']"),
    ({"shape": [1.0], "goal": np.zeros(5), "vias": np.zeros((5, 3)), "Pd": np.zeros((3, 0))},
     "'shape' must be 2 x 1"),
    ({"shape": [1.0, 2.0], "goal": np.zeros(5), "vias": np.zeros((3, 5)),
      "Pd": np.zeros((3, 0))}, "'vias' must be 5 x 3"),
])
def test_a_wrong_name_or_shape_is_refused(values: dict[str, object], words: str) -> None:
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
        DECL.pack(values)  # type: ignore[arg-type]
