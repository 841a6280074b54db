"""``wott-hub bench fields``: displacement fields and raw images through wott-client (issue 29)."""
