"""The model compiled into index maps and constant matrices giving Φ, Φ_q, ν and γ."""

from fccgrb_cli.system.compiled import DRIVER, TOPOLOGY, TRACKING, Drive, System, compile_system
from fccgrb_cli.system.layout import Layout

__all__ = ["DRIVER", "TOPOLOGY", "TRACKING", "Drive", "Layout", "System", "compile_system"]
