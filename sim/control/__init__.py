"""CONTROLLERS: the MTS-469D-style three-variable controller (``tvc``), the analog PIDF+dP controller (``analog``) and off-line drive-signal iteration (``iteration``)."""
