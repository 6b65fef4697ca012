"""A corpus: many sessions run as independent tasks.

`sessions.py` turns what a user typed (files, globs, folders) into one ordered list of session files;
`executor.py` runs one function per session in local worker processes or on a Ray cluster, retrying a
session whose worker died once and reporting it failed after that, without stopping the others.
Export and eval both use it; it imports nothing of teleprev but the ground floor.
"""
