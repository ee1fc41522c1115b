"""esper processors, one module per phase; each declares ``phase`` (and ``order`` within it)."""
