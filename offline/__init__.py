"""Offline training: importers and fitters that write tables for the runtime."""
