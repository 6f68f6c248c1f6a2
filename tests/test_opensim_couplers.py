"""Chained CoordinateCouplerConstraints (one coupler's dependent the next one's independent), in
either document order: the default pose, the coordinates the markers see and the first frame's
guess follow the chain as OpenSim's assembly does; a loop of couplers or a coordinate coupled
twice is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.observed import unobserved
from fccgrb_cli.model.osim.convert import parse_osim_model
from fccgrb_cli.pipeline.options import _held
from fccgrb_cli.solvers.moving_initial import moving_initial_guess
from fccgrb_cli.system import compile_system
from tests.osim_text import BODY, COORDINATE

LINEAR = "<LinearFunction><coefficients>{} {}</coefficients></LinearFunction>"
# c2 = 0.5 c1 − 0.2 and c3 = 2 c2 + 0.1; c1's default is 0.4
EARLY = ("early", "c1", "c2", LINEAR.format(0.5, -0.2))
LATE = ("late", "c2", "c3", LINEAR.format(2.0, 0.1))


def _pin(name: str, parent: str, child: str, coordinate: str, default: float) -> str:
    return (f'<PinJoint name="{name}"><socket_parent_frame>{parent}</socket_parent_frame>'
            f'<socket_child_frame>{child}</socket_child_frame><coordinates>'
            + COORDINATE.format(name=coordinate, motion="rotational", default=default,
                                locked="false")
            + "</coordinates></PinJoint>")


def _coupler(name: str, independent: str, dependent: str, function: str) -> str:
    return (f'<CoordinateCouplerConstraint name="{name}"><coupled_coordinates_function>'
            f'{function}</coupled_coordinates_function><independent_coordinate_names>'
            f'{independent}</independent_coordinate_names><dependent_coordinate_name>'
            f'{dependent}</dependent_coordinate_name></CoordinateCouplerConstraint>')


def chain_model(couplers: list[tuple[str, str, str, str]]) -> str:
    """Three bodies on pins from the ground, each turned by its own coordinate c1, c2, c3 (the
    documents' defaults 0.4, 0.7, 0.9 are not the chain's: OpenSim assembles the dependents);
    markers only on the third body, which c1 moves only through the chain."""
    bodies = "".join(BODY.format(name=n, mass=1.0, com="0 0 0", inertia="0.1 0.1 0.1 0 0 0")
                     for n in ("s1", "s2", "s3"))
    joints = (_pin("p1", "/ground", "/bodyset/s1", "c1", 0.4)
              + _pin("p2", "/ground", "/bodyset/s2", "c2", 0.7)
              + _pin("p3", "/ground", "/bodyset/s3", "c3", 0.9))
    markers = "".join(f'<Marker name="{n}"><socket_parent_frame>/bodyset/s3</socket_parent_frame>'
                      f'<location>{loc}</location></Marker>'
                      for n, loc in (("A", "0.3 0 0"), ("B", "0 0.2 0.1")))
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><Model name="chain"><Ground name="ground"/>
<BodySet><objects>{bodies}</objects></BodySet><JointSet><objects>{joints}</objects></JointSet>
<ConstraintSet><objects>{"".join(_coupler(*c) for c in couplers)}</objects></ConstraintSet>
<MarkerSet><objects>{markers}</objects></MarkerSet></Model></OpenSimDocument>"""


ORDERS = pytest.mark.parametrize("couplers", [[EARLY, LATE], [LATE, EARLY]],
                                 ids=["in order", "reversed"])


@ORDERS
def test_the_default_pose_follows_the_whole_chain(couplers):
    model = parse_osim_model(chain_model(couplers), "chain.osim")
    defaults = {c.name: c.default for c in model.angles}
    assert defaults["c2"] == pytest.approx(0.5 * 0.4 - 0.2, abs=1e-15)
    assert defaults["c3"] == pytest.approx(2.0 * defaults["c2"] + 0.1, abs=1e-15)
    # the third body stands where its coordinate turns it
    w = np.array(model.body("s3").pose.u)
    assert np.allclose(w, [np.cos(defaults["c3"]), np.sin(defaults["c3"]), 0.0], atol=1e-15)


@ORDERS
def test_a_coordinate_that_moves_markers_only_through_the_chain_is_seen(couplers):
    model = parse_osim_model(chain_model(couplers), "chain.osim")
    assert unobserved(model) == []


@ORDERS
def test_the_first_guess_couples_a_held_independent_down_the_chain(couplers):
    model = _held(parse_osim_model(chain_model(couplers), "chain.osim"), ("c1=10",))
    system = compile_system(model, angles="coordinate")
    targets = np.full((len(model.tracked_points), 3), np.nan)  # no marker: the defaults
    q = moving_initial_guess(system, targets)
    theta = dict(zip((c.name for c in model.angles), q[system.layout.n_body_q:], strict=True))
    assert theta["c1"] == pytest.approx(np.radians(10.0), abs=1e-15)
    assert theta["c2"] == pytest.approx(0.5 * theta["c1"] - 0.2, abs=1e-15)
    assert theta["c3"] == pytest.approx(2.0 * theta["c2"] + 0.1, abs=1e-15)


@pytest.mark.parametrize("couplers, message", [
    ([EARLY, ("back", "c2", "c1", LINEAR.format(2.0, 0.4))], "form a loop: early → back"),
    ([EARLY, ("again", "c3", "c2", LINEAR.format(1.0, 0.0))],
     "coordinate 'c2' is already the dependent of early"),
], ids=["loop", "twice"])
def test_a_loop_or_a_twice_coupled_coordinate_is_refused_in_one_line(couplers, message):
    with pytest.raises(InputError) as error:
        parse_osim_model(chain_model(couplers), "chain.osim")
    text = str(error.value)
    assert "\n" not in text and text.startswith("chain.osim: ") and message in text
    assert "ConstraintSet" in text
