"""The planar payload's gap diagnosis: prepared data, accelerations compared, verdict, report and validation."""
