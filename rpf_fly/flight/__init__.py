"""The flight: per-drone planners on their own local views, the supervisor, the flight loop, the dry run
(docs/flight.md)."""
