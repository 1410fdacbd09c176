"""Built-in algorithm plugins, each in its own folder, registered through entry points."""
