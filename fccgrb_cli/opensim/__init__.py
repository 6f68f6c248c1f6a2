"""OpenSim's data in and out: storage files (``.mot``/``.sto``), external loads and the plates'
bodies, the IK and ID tools' setups and task sets. OpenSim's models are read in the model layer
(``model.osim``); strangers' XML by ``core.xml``."""
