"""The soak rack: units powered and logged at rest from power-on (relay board, logging, recordings)."""
