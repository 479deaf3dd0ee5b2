#!/usr/bin/env python3
# Writes terraces.city.json (CityJSON 2.0): LoD2 surface models as cities publish them (issue 46),
# each building one MultiSurface of walls, roofs and ground, not closed on its own, for the
# shell closure end to end (import, check-conservative, a served walk with --verify):
#   - a row of four houses without party walls (r1..r4); the end house r4 lacks its end wall
#     too (its neighbour is not in the data): r4 is open to the air, r1..r3 are closed by each
#     other and r3 draws the party wall it shares with r4;
#   - r3's west corners 1 mm east of r2's east corners (welded);
#   - two houses whose shared opening is bent out of any plane and off the vertical (b1, b2):
#     the ground edge straight, the roof edge out to a corner 1 m off it; closed together;
#   - a house without a floor (f), closed by the ground;
#   - a small closed house (h) behind the row, and a long one (w) behind that, for something to
#     hide; a road all round (the ground, and the street in front of the row).
# Coordinates as in the shapes files (EPSG:28992 metres around (85000, 446000)); faces outward.
# Run from this folder: python3 make_terraces_cityjson.py
from fractions import Fraction

from make_shapes_cityjson import P, face, box_faces
from make_floorless_cityjson import write

MM = Fraction(1, 1000)


def house(x0, x1, y0, y1, z, west=True, east=True, west_dx=Fraction(0)):
    """A box x0..x1, y0..y1, 0..z with its west and east walls left out unless asked for;
    the west corners moved by west_dx in x (a millimetre gap)."""
    xa, xb = Fraction(x0) + west_dx, Fraction(x1)
    f = [face([P(xa, y0, 0), P(xa, y1, 0), P(xb, y1, 0), P(xb, y0, 0)]),      # floor
         face([P(xa, y0, 0), P(xb, y0, 0), P(xb, y0, z), P(xa, y0, z)]),      # south (the street)
         face([P(xb, y1, 0), P(xa, y1, 0), P(xa, y1, z), P(xb, y1, z)]),      # north
         face([P(xa, y0, z), P(xb, y0, z), P(xb, y1, z), P(xa, y1, z)])]      # roof
    if east:
        f.append(face([P(xb, y0, 0), P(xb, y1, 0), P(xb, y1, z), P(xb, y0, z)]))
    if west:
        f.append(face([P(xa, y1, 0), P(xa, y0, 0), P(xa, y0, z), P(xa, y1, z)]))
    return f


def bent_pair(x, y):
    """Two houses 5 + 5 m wide, 8 deep, 6 high; their shared opening's ground edge along
    x + 5, its roof edge out to (x + 6, y + 4)."""
    def p(a, b, c):
        return P(x + a, y + b, c)
    a = [face([p(0, 0, 0), p(0, 8, 0), p(5, 8, 0), p(5, 0, 0)]),
         face([p(0, 0, 6), p(5, 0, 6), p(6, 4, 6), p(5, 8, 6), p(0, 8, 6)]),
         face([p(0, 0, 0), p(5, 0, 0), p(5, 0, 6), p(0, 0, 6)]),
         face([p(5, 8, 0), p(0, 8, 0), p(0, 8, 6), p(5, 8, 6)]),
         face([p(0, 8, 0), p(0, 0, 0), p(0, 0, 6), p(0, 8, 6)])]
    b = [face([p(5, 0, 0), p(5, 8, 0), p(10, 8, 0), p(10, 0, 0)]),
         face([p(5, 0, 6), p(10, 0, 6), p(10, 8, 6), p(5, 8, 6), p(6, 4, 6)]),
         face([p(5, 0, 0), p(10, 0, 0), p(10, 0, 6), p(5, 0, 6)]),
         face([p(10, 8, 0), p(5, 8, 0), p(5, 8, 6), p(10, 8, 6)]),
         face([p(10, 0, 0), p(10, 8, 0), p(10, 8, 6), p(10, 0, 6)])]
    return a, b


b1, b2 = bent_pair(40, 0)
TERRACES = [
    ('r1', 'Building', ('MultiSurface', '2', house(0, 6, 0, 10, 9, west=True, east=False))),
    ('r2', 'Building', ('MultiSurface', '2', house(6, 12, 0, 10, 9, west=False, east=False))),
    ('r3', 'Building', ('MultiSurface', '2', house(12, 18, 0, 10, 9, west=False, east=False, west_dx=MM))),
    ('r4', 'Building', ('MultiSurface', '2', house(18, 24, 0, 10, 9, west=False, east=False))),
    ('b1', 'Building', ('MultiSurface', '2', b1)),
    ('b2', 'Building', ('MultiSurface', '2', b2)),
    ('f', 'Building', ('MultiSurface', '2', box_faces(60, 0, 0, 68, 8, 7)[1:])),
    ('h', 'Building', ('MultiSurface', '2', box_faces(8, 16, 0, 14, 22, 4))),
    ('w', 'Building', ('MultiSurface', '2', box_faces(0, 30, 0, 70, 36, 12))),
    ('road', 'Road', ('MultiSurface', '2', [face([P(-20, -30, 0), P(90, -30, 0), P(90, 50, 0), P(-20, 50, 0)])])),
]

if __name__ == '__main__':
    write('terraces.city.json', TERRACES)
