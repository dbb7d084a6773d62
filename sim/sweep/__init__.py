"""MANY: run one function over many cases (serial or a process pool)."""
