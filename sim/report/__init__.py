"""PRESENT: rerun recordings, figures and markdown reports."""
