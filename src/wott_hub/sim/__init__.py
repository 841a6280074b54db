"""Simulation support shared by every device family's simulator: scripted scenes."""
