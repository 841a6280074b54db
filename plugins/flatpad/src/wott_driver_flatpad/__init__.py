"""wott-hub driver plugin."""
