"""The ``lidarqa`` command line (click).

The group is in ``main.py``; each command family has its own module.
"""
