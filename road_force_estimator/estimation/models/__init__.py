"""The vehicle models the observer estimates: each hands the filters its linear state space with
the unknown inputs, its measurement map and its reconstruction; the filters never know which
truck it is. :mod:`.front_axle`: MODEL.md's roll-plane front axle (the default).
"""
