"""File formats: each reader gives a file-faithful result, then one conversion to `Motion`."""
