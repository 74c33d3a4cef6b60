"""YAML text -> validated Config: the reader, expressions and the config models."""
