"""WHAT IS IT: least-squares identification of a table mechanical model and the characterisation programme (estimates only; never writes a description)."""
