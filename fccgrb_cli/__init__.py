"""fccgrb: FCC-GRB multibody kinematics and inverse dynamics with mixed coordinates.

Gonçalves, Roupa, Flores, Tavares da Silva, Mechanism and Machine Theory 214 (2025) 106080.
"""

__version__ = "0.1.0"
