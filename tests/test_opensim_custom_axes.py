"""A CustomJoint two of whose rotation (or translation) axes are collinear is refused in one
line, as OpenSim 4.6 refuses it on loading ("has collinear axes and are not well-defined"),
constant axes included; axes just apart of OpenSim's tolerance load."""

from __future__ import annotations

import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.osim.convert import parse_osim_model
from tests.osim_text import COORDINATE, LINEAR, ZERO, axis, custom_joint

AXES = {"rotation1": "0 0 1", "rotation2": "1 0 0", "rotation3": "0 1 0",
        "translation1": "1 0 0", "translation2": "0 1 0", "translation3": "0 0 1"}


def _model(**changed: str) -> str:
    directions = {**AXES, **changed}
    axes = [axis(name, "q" if name == "rotation1" else "", direction,
                 LINEAR if name == "rotation1" else ZERO)
            for name, direction in directions.items()]
    joint = custom_joint("j", "/ground", "/bodyset/b",
                         [COORDINATE.format(name="q", motion="rotational", default=0.0,
                                            locked="false")], axes)
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><Model name="axes"><Ground name="ground"/>
<BodySet><objects><Body name="b"><mass>1</mass><mass_center>0 0 0</mass_center>
<inertia>0.1 0.1 0.1 0 0 0</inertia></Body></objects></BodySet>
<JointSet><objects>{joint}</objects></JointSet></Model></OpenSimDocument>"""


@pytest.mark.parametrize("changed, pair", [
    ({"rotation3": "0 0 -2"}, "rotation1 and rotation3"),
    ({"rotation2": "0 1e-6 1"}, "rotation1 and rotation2"),
    ({"translation2": "3 0 0"}, "translation1 and translation2"),
], ids=["opposite", "nearly", "translations"])
def test_collinear_axes_are_refused_in_one_line(changed, pair):
    with pytest.raises(InputError) as error:
        parse_osim_model(_model(**changed), "axes.osim")
    text = str(error.value)
    assert "\n" not in text and text.startswith("axes.osim: ")
    assert "SpatialTransform" in text and f"{pair} have collinear axes" in text


def test_axes_apart_by_more_than_opensims_tolerance_load():
    model = parse_osim_model(_model(rotation2="0 1e-4 1", rotation3="1 0 0",
                                    translation2="1 1e-4 0", translation3="0 0 1"),
                             "axes.osim")
    assert model.moving_joints[0].name == "j"
