"""A GCVSpline's degree is read from its ``half_order`` (degree = 2 · half_order − 1), the only
property OpenSim writes for it: numbers OpenSim 4.6 computed, so no OpenSim is needed."""

from __future__ import annotations

import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.osim.convert import parse_osim_model
from tests.osim_text import knee_model

XS = "-2 -1.2 -0.5 0 0.4 1 1.6 2.1"
YS = "-0.003 0.002 0.004 0.001 -0.003 -0.005 0.001 0.002"
# OpenSim 4.6: GCVSpline.setDegree(2 · half_order − 1) through (XS, YS), then calcValue at x
OPENSIM = {
    1: {-2.5: -0.0029999999999999988, -1.6: -0.0005000000000000004, -0.2: 0.0021999999999999997,
        0.7: -0.003999999999999998, 1.8: 0.0013999999999999991, 2.6: 0.002},
    2: {-2.5: -0.006276542897076119, -1.6: -0.0004090742617543306, -0.2: 0.0026351268090231855,
        0.7: -0.005107875158319945, 1.8: 0.0019185510998528002, 2.6: 0.0016496065108000013},
    3: {-2.5: -0.005764997916431301, -1.6: -0.0005369990101570093, -0.2: 0.0026381567978607163,
        0.7: -0.005164413791478061, 1.8: 0.0023163857093692203, 2.6: -0.005126787779624294},
    4: {-2.5: -0.002544428091912526, -1.6: -0.0008004630860672628, -0.2: 0.0026395122226325536,
        0.7: -0.00509265975002054, 1.8: 0.0026833156099941116, 2.6: -0.015333190996713346},
}


def _spline(inside: str):
    """The test knee's x translation, a GCVSpline with ``inside`` before its points."""
    text = knee_model(function=f"<GCVSpline>{inside}<error_variance>0</error_variance>"
                               f"<x>{XS}</x><y>{YS}</y></GCVSpline>")
    return parse_osim_model(text, "gcv.osim").moving_joints[1].transform.axes[3].function


@pytest.mark.parametrize("half_order", sorted(OPENSIM))
def test_a_gcv_spline_has_the_degree_its_half_order_gives_as_in_opensim(half_order):
    function = _spline(f"<half_order>{half_order}</half_order>")
    for x, value in OPENSIM[half_order].items():
        assert function.terms(x)[0] == pytest.approx(value, abs=1e-13)  # degree 7: 2e-14


@pytest.mark.parametrize("inside, message", [
    ("", "expected a <half_order>"),
    ("<half_order>5</half_order>", "expected half_order 1, 2, 3 or 4"),
], ids=["missing", "unknown"])
def test_a_gcv_spline_without_a_known_half_order_is_refused(inside, message):
    with pytest.raises(InputError, match=message) as error:
        _spline(inside)
    assert "\n" not in str(error.value) and str(error.value).startswith("gcv.osim: ")
