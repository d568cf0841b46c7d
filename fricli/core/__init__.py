"""Contracts and files: exit codes, atomic writes, the log contract, the joint rule, model files."""
