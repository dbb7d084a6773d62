"""Signal processing and estimators every layer shares: FRF (Welch, H1/H2/instrumental), peak picking, first/second-order fits, friction and hysteresis fits."""
