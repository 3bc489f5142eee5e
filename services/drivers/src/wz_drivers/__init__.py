"""Field sensor drivers: real devices' formats in, the bus's messages out (see records.py)."""
