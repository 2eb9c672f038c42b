"""Code charts (SPEC §3.5, §5): numbered lists of code mnemonics, one chart per link and direction.

A code's number is its 1-based position in the chart (Table 2 "Sequence"); Type I ALL_INFO byte k-1
carries code k. This package loads, generates and checks charts; it touches no link.
"""
