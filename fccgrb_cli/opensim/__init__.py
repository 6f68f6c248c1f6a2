"""OpenSim's files in and out: models (``.osim``), storage files (``.mot``/``.sto``), external
loads and the IK/ID tools' setups, read as strangers' files (``opensim.xml``)."""
