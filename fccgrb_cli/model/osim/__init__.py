"""OpenSim's models (``.osim``, 3.x and 4.x layouts) read as fccgrb models: the document
(``document``), OpenSim's functions of coordinates (``functions``) and the conversion into a
:class:`~fccgrb_cli.model.Model` whose moving joints carry every OpenSim coordinate as a mixed
coordinate (``convert``; docs/opensim.md)."""
