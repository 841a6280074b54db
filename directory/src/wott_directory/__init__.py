"""A W3C WoT Thing Description Directory."""
