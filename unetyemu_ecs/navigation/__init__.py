"""PX4-style navigation on the flight stack: flight modes (HOLD, TAKEOFF, LAND, RTL, MISSION, OFFBOARD ...),
the landed detector, home, flight parameters, geofence and rally points (docs/architecture.md §7)."""
