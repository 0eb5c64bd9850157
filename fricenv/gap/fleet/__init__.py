"""Fleet diagnosis: every log of a folder or glob pattern diagnosed into its own report, and the fleet summary."""
