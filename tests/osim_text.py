"""Small OpenSim 4.x model documents written by the tests (no OpenSim needed)."""

from __future__ import annotations

BODY = """<Body name="{name}"><mass>{mass}</mass><mass_center>{com}</mass_center>
<inertia>{inertia}</inertia></Body>"""

FRAME = """<PhysicalOffsetFrame name="{name}"><socket_parent>{parent}</socket_parent>
<translation>{translation}</translation><orientation>{orientation}</orientation>
</PhysicalOffsetFrame>"""

COORDINATE = """<Coordinate name="{name}"><motion_type>{motion}</motion_type>
<default_value>{default}</default_value><range>-3 3</range><locked>{locked}</locked>
<clamped>false</clamped></Coordinate>"""


def named(function: str, name: str = "function") -> str:
    """A function element as OpenSim 4 writes a property: ``<SimmSpline name="function">``."""
    tag_end = function.index(">")
    return f'{function[:tag_end]} name="{name}"{function[tag_end:]}'


def axis(name: str, coordinate: str, direction: str, function: str) -> str:
    return (f'<TransformAxis name="{name}"><coordinates>{coordinate}</coordinates>'
            f'<axis>{direction}</axis>{named(function)}</TransformAxis>')


def custom_joint(name: str, parent: str, child: str, coordinates: list[str], axes: list[str],
                 parent_offset: tuple[str, str] = ("0.1 -0.2 0.05", "0.2 -0.1 0.3"),
                 child_offset: tuple[str, str] = ("0 0.3 0", "-0.1 0.2 0")) -> str:
    frames = (FRAME.format(name=f"{name}_p", parent=parent, translation=parent_offset[0],
                           orientation=parent_offset[1])
              + FRAME.format(name=f"{name}_c", parent=child, translation=child_offset[0],
                             orientation=child_offset[1]))
    return (f'<CustomJoint name="{name}"><socket_parent_frame>{name}_p</socket_parent_frame>'
            f'<socket_child_frame>{name}_c</socket_child_frame>'
            f'<coordinates>{"".join(coordinates)}</coordinates><frames>{frames}</frames>'
            f'<SpatialTransform>{"".join(axes)}</SpatialTransform></CustomJoint>')


def simm(xs: str, ys: str) -> str:
    return f"<SimmSpline><x>{xs}</x><y>{ys}</y></SimmSpline>"


LINEAR = "<LinearFunction><coefficients>1 0</coefficients></LinearFunction>"
ZERO = "<Constant><value>0</value></Constant>"


def knee_model(*, marker_body: str = "/bodyset/shank", parent: str = "/bodyset/thigh",
               function: str | None = None, extra_body: str = "",
               coupler: str = "", locked: str = "false") -> str:
    """Ground → free thigh (a CustomJoint with 6 coordinates) → shank (a CustomJoint whose
    rotation is the knee angle and whose translations are splines of it)."""
    hip_coordinates = [COORDINATE.format(name=n, motion=m, default=d, locked="false")
                       for n, m, d in (("rx", "rotational", 0.1), ("ry", "rotational", -0.2),
                                       ("rz", "rotational", 0.3), ("tx", "translational", 0.1),
                                       ("ty", "translational", 0.9),
                                       ("tz", "translational", -0.05))]
    hip_axes = [axis("rotation1", "rz", "0 0 1", LINEAR), axis("rotation2", "rx", "1 0 0", LINEAR),
                axis("rotation3", "ry", "0 1 0", LINEAR),
                axis("translation1", "tx", "1 0 0", LINEAR),
                axis("translation2", "ty", "0 1 0", LINEAR),
                axis("translation3", "tz", "0 0 1", LINEAR)]
    spline = function or simm("-2 -1.2 -0.5 0 0.4 1", "-0.003 0.002 0.004 0.001 -0.003 -0.005")
    knee_coordinates = [COORDINATE.format(name="knee", motion="rotational", default=-0.6,
                                          locked=locked),
                        COORDINATE.format(name="patella", motion="rotational", default=0.0,
                                          locked="false")]
    knee_axes = [axis("rotation1", "knee", "0 0 1", LINEAR),
                 axis("rotation2", "", "0 1 0", ZERO),
                 axis("rotation3", "patella", "1 0 0", LINEAR),
                 axis("translation1", "knee", "1 0 0", spline),
                 axis("translation2", "knee", "0 1 0",
                      "<MultiplierFunction>"
                      + named(simm("-2 -1 0 1", "-0.42 -0.41 -0.40 -0.395"))
                      + "<scale>1.1</scale></MultiplierFunction>"),
                 axis("translation3", "", "0 0 1", ZERO)]
    joints = (custom_joint("hip", "/ground", "/bodyset/thigh", hip_coordinates, hip_axes,
                           ("0 0 0", "0 0 0"), ("0 0 0", "0 0 0"))
              + custom_joint("knee", parent, "/bodyset/shank", knee_coordinates, knee_axes))
    bodies = (BODY.format(name="thigh", mass=8.0, com="0 -0.2 0.01",
                          inertia="0.12 0.03 0.11 0.002 -0.001 0.004")
              + BODY.format(name="shank", mass=3.5, com="0.01 -0.18 0",
                            inertia="0.05 0.006 0.05 0.001 0 0.0005") + extra_body)
    markers = "".join(
        f'<Marker name="{n}"><socket_parent_frame>{b}</socket_parent_frame>'
        f'<location>{loc}</location></Marker>'
        for n, b, loc in (("T1", "/bodyset/thigh", "0.05 -0.1 0.06"),
                          ("T2", "/bodyset/thigh", "-0.04 -0.25 0.05"),
                          ("T3", "/bodyset/thigh", "0.03 -0.35 -0.06"),
                          ("S1", marker_body, "0.05 -0.1 0.05"),
                          ("S2", "/bodyset/shank", "-0.05 -0.3 0.04"),
                          ("S3", "/bodyset/shank", "0.02 -0.38 -0.05")))
    return f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><Model name="knee">
<gravity>0 -9.80665 0</gravity><length_units>meters</length_units>
<Ground name="ground"/>
<BodySet><objects>{bodies}</objects></BodySet>
<JointSet><objects>{joints}</objects></JointSet>
<ConstraintSet><objects>{coupler}</objects></ConstraintSet>
<ForceSet><objects><Thelen2003Muscle name="m"/></objects></ForceSet>
<MarkerSet><objects>{markers}</objects></MarkerSet>
</Model></OpenSimDocument>
"""
