"""GelSight Mini and DIGIT (docs/gel.md)."""
