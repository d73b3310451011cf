"""The networks: CCHP (`cchp`), the RANP and Dummy LSTM baselines, and their shared blocks."""
