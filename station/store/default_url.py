"""Where the unit store lives by default (kept apart so that naming it imports no database code)."""

DEFAULT_URL = "sqlite:///station.sqlite"  # in the working directory
ENV_VAR = "STATION_DB"  # overrides the default URL
