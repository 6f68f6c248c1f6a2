"""Conventions of OpenSim's own reading that an imported model's forward kinematics must share
with it (found by benchmarks/opensim_fk.py, which compares fccgrb with OpenSim 4.6 itself): each
test holds numbers OpenSim computed, so it needs no OpenSim to run."""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.model.osim.convert import parse_osim_model
from fccgrb_cli.model.osim.functions import SimmSpline
from fccgrb_cli.system import compile_system
from fccgrb_cli.system.moving_pose import pose_from_coordinates
from tests.osim_text import knee_model

XS, YS = "-2 -1.2 -0.5 0 0.4 1", "-0.003 0.002 0.004 0.001 -0.003 -0.005"
# OpenSim 4.6's SimmSpline through (XS, YS), calcValue at these points (inside and outside them)
OPENSIM_VALUES = {-2.5: -0.0053894813640117094, -1.6: -0.0006303979305857929,
                  -0.8: 0.003857120523984686, -0.2: 0.002629899341265671,
                  0.7: -0.005088580648036934, 1.4: -0.0028971182719015106}


def _knee(tag: str):
    """The test knee whose shank slides along x by a spline of the knee angle written as
    ``<tag>``."""
    return parse_osim_model(knee_model(function=f"<{tag}><x>{XS}</x><y>{YS}</y></{tag}>"),
                            f"{tag}.osim")


@pytest.mark.parametrize("tag", ["SimmSpline", "NaturalCubicSpline", "natCubicSpline"])
def test_old_natural_cubic_splines_are_read_as_opensim_reads_them_as_simm_splines(tag):
    # OpenSim renames both old tags to SimmSpline on reading (the old "natural" spline was not
    # one); a 2.x knee read as a true natural spline sat up to 0.27 mm off OpenSim's
    # (opensim-core's gait2392 ID regression model)
    model = _knee(tag)
    function = model.moving_joints[1].transform.axes[3].function
    assert isinstance(function, SimmSpline)
    for x, value in OPENSIM_VALUES.items():
        assert function.terms(x)[0] == pytest.approx(value, abs=1e-15)
    # and the bodies follow: the shank where the SimmSpline knee puts it, at several angles
    reference = compile_system(_knee("SimmSpline"), angles="coordinate")
    system = compile_system(model, angles="coordinate")
    knee = [a.name for a in model.angles].index("knee")
    shank = system.layout.q_slice("shank")
    for angle in OPENSIM_VALUES:
        theta = system.functions.defaults.copy()
        theta[knee] = angle
        assert np.allclose(pose_from_coordinates(system, theta)[shank],
                           pose_from_coordinates(reference, theta)[shank], rtol=0, atol=1e-15)
