"""Tests of gap."""
