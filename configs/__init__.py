"""Machine profiles shipped with nurbsfeed (selected by name with `--machine NAME`)."""
