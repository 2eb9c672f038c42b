"""Deterministic scenario runs: YAML scenario → endpoints in virtual time → assertions → report."""
