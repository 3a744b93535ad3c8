"""One router per resource: localization, maps, operations (probes and metrics)."""
