"""Signal conditioning of logged channels: sensor artifacts, stated filters, speed reconstructed from a wheel."""
