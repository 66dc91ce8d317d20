"""Utilities every floor may use: resource paths, native builds, bounded histories."""
