"""Investigations: each answered one question (why a figure is what it is, whether a setting
earns its place); their conclusions are in docs/ and docs/notes/, and each script is kept as
the command that reproduces its note."""
