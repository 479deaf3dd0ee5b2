#!/usr/bin/env python3
# Writes shapes.gml (CityGML 2.0) and shapes_v1.gml (CityGML 1.0: the gabled house and the stacked
# parts) with exactly the rings of shapes.city.json: the geometry functions below are copied from
# make_shapes_cityjson.py (the CityJSON files' generator; keep the two in step). Rings: outer rings
# counter-clockwise seen from outside the solid, holes clockwise; each ring starts at its corner of
# least (z, x, y) and is written closed (first point repeated), as GML requires. Faces of a solid:
# bottom faces (floor first), walls counter-clockwise seen from above starting at the wall at min y
# (lower tier first), then top faces (roofs).
#
# LoD2 solids are written as the Den Haag file does: the solid's surfaceMembers are xlink:hrefs to
# the gml:ids of the polygons of the building's bldg:boundedBy surfaces (GroundSurface,
# WallSurface, RoofSurface, OuterFloorSurface), in face order. LoD1 solids (courtyard, bridge) hold
# their polygons inline. Run from this folder: python3 make_shapes_citygml.py
from fractions import Fraction

X0, Y0 = 85000, 446000          # the README's offsets: objects are given relative to these
TRANSLATE = [84990.0, 445980.0, 0.0]
SCALE = 0.001                   # millimetres: every coordinate below is a whole number of them


def P(x, y, z):
    return (Fraction(x) + X0, Fraction(y) + Y0, Fraction(z))


def start_least(ring):
    i = min(range(len(ring)), key=lambda k: (ring[k][2], ring[k][0], ring[k][1]))
    return ring[i:] + ring[:i]


def newell(ring):
    n = [Fraction(0)] * 3
    for a, b in zip(ring, ring[1:] + ring[:1]):
        n[0] += (a[1] - b[1]) * (a[2] + b[2])
        n[1] += (a[2] - b[2]) * (a[0] + b[0])
        n[2] += (a[0] - b[0]) * (a[1] + b[1])
    return n


def face(outer, *holes):
    return [start_least(outer)] + [start_least(h) for h in holes]


def box_faces(x0, y0, z0, x1, y1, z1, roof=True):
    f = [face([P(x0, y0, z0), P(x0, y1, z0), P(x1, y1, z0), P(x1, y0, z0)]),   # floor
         face([P(x0, y0, z0), P(x1, y0, z0), P(x1, y0, z1), P(x0, y0, z1)]),   # south (min y)
         face([P(x1, y0, z0), P(x1, y1, z0), P(x1, y1, z1), P(x1, y0, z1)]),   # east
         face([P(x1, y1, z0), P(x0, y1, z0), P(x0, y1, z1), P(x1, y1, z1)]),   # north
         face([P(x0, y1, z0), P(x0, y0, z0), P(x0, y0, z1), P(x0, y1, z1)])]   # west
    if roof:
        f.append(face([P(x0, y0, z1), P(x1, y0, z1), P(x1, y1, z1), P(x0, y1, z1)]))
    return f


def check_closed(name, faces):
    # Every directed edge once, and its reverse once: closed and consistently oriented.
    edges = {}
    for f in faces:
        for r in f:
            for a, b in zip(r, r[1:] + r[:1]):
                assert (a, b) not in edges, (name, a, b)
                edges[(a, b)] = True
    for a, b in edges:
        assert (b, a) in edges, (name, 'open edge', a, b)
    # Outward: positive volume (divergence theorem over the faces' Newell normals).
    vol = Fraction(0)
    for f in faces:
        for r in f:
            o = r[0]
            for a, b in zip(r[1:], r[2:]):
                u = [a[i] - o[i] for i in range(3)]
                v = [b[i] - o[i] for i in range(3)]
                c = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
                vol += sum(o[i] * c[i] for i in range(3)) / 6
    assert vol > 0, (name, vol)
    return vol


def gabled():
    f = [face([P(0, 0, 0), P(0, 8, 0), P(10, 8, 0), P(10, 0, 0)]),
         face([P(0, 0, 0), P(10, 0, 0), P(10, 0, 6), P(0, 0, 6)]),
         face([P(10, 0, 0), P(10, 8, 0), P(10, 8, 6), P(10, 4, 9), P(10, 0, 6)]),
         face([P(10, 8, 0), P(0, 8, 0), P(0, 8, 6), P(10, 8, 6)]),
         face([P(0, 8, 0), P(0, 0, 0), P(0, 0, 6), P(0, 4, 9), P(0, 8, 6)]),
         face([P(0, 0, 6), P(10, 0, 6), P(10, 4, 9), P(0, 4, 9)]),
         face([P(10, 8, 6), P(0, 8, 6), P(0, 4, 9), P(10, 4, 9)])]
    assert check_closed('gabled', f) == 10 * 8 * 6 + 10 * 8 * 3 / 2
    return f


def tower():
    podium = box_faces(20, 0, 0, 40, 20, 5, roof=False)
    tw = box_faces(26, 6, 5, 34, 14, 30)
    podium_roof = face([P(20, 0, 5), P(40, 0, 5), P(40, 20, 5), P(20, 20, 5)],
                       [P(26, 6, 5), P(26, 14, 5), P(34, 14, 5), P(34, 6, 5)])
    f = podium + tw[1:5] + [podium_roof, tw[5]]
    assert check_closed('tower', f) == 20 * 20 * 5 + 8 * 8 * 25
    return f


def overhang():
    f = [face([P(70, 0, 0), P(70, 6, 0), P(80, 6, 0), P(80, 0, 0)]),                    # floor
         face([P(70, 6, 3), P(70, 10, 3), P(80, 10, 3), P(80, 6, 3)]),                  # underside
         face([P(70, 0, 0), P(80, 0, 0), P(80, 0, 6), P(70, 0, 6)]),                    # south
         face([P(80, 0, 0), P(80, 6, 0), P(80, 6, 3), P(80, 10, 3), P(80, 10, 6), P(80, 0, 6)]),
         face([P(80, 6, 0), P(70, 6, 0), P(70, 6, 3), P(80, 6, 3)]),                    # north, lower
         face([P(80, 10, 3), P(70, 10, 3), P(70, 10, 6), P(80, 10, 6)]),                # north, upper
         face([P(70, 10, 3), P(70, 6, 3), P(70, 6, 0), P(70, 0, 0), P(70, 0, 6), P(70, 10, 6)]),
         face([P(70, 0, 6), P(80, 0, 6), P(80, 10, 6), P(70, 10, 6)])]                  # roof
    assert check_closed('overhang', f) == 10 * 6 * 3 + 10 * 10 * 3
    return f


def courtyard():
    ox0, oy0, ox1, oy1, ix0, iy0, ix1, iy1 = 100, 0, 120, 20, 106, 6, 114, 14
    floor = face([P(ox0, oy0, 0), P(ox0, oy1, 0), P(ox1, oy1, 0), P(ox1, oy0, 0)],
                 [P(ix0, iy0, 0), P(ix1, iy0, 0), P(ix1, iy1, 0), P(ix0, iy1, 0)])
    outer_walls = box_faces(ox0, oy0, 0, ox1, oy1, 10)[1:5]
    # Inner walls face into the courtyard; counter-clockwise from the one at min y.
    inner_walls = [face([P(ix1, iy0, 0), P(ix0, iy0, 0), P(ix0, iy0, 10), P(ix1, iy0, 10)]),
                   face([P(ix1, iy1, 0), P(ix1, iy0, 0), P(ix1, iy0, 10), P(ix1, iy1, 10)]),
                   face([P(ix0, iy1, 0), P(ix1, iy1, 0), P(ix1, iy1, 10), P(ix0, iy1, 10)]),
                   face([P(ix0, iy0, 0), P(ix0, iy1, 0), P(ix0, iy1, 10), P(ix0, iy0, 10)])]
    roof = face([P(ox0, oy0, 10), P(ox1, oy0, 10), P(ox1, oy1, 10), P(ox0, oy1, 10)],
                [P(ix0, iy0, 10), P(ix0, iy1, 10), P(ix1, iy1, 10), P(ix1, iy0, 10)])
    f = [floor] + outer_walls + inner_walls + [roof]
    assert check_closed('courtyard', f) == (400 - 64) * 10
    return f


def closed_box(name, *a):
    f = box_faces(*a)
    check_closed(name, f)
    return f


def terrain():
    xs, ys = [130, 140, 150, 160], [-10, 0, 10, 20]
    # Height 0 at x 85130 rising linearly to 5 at x 85160: 0, 5/3, 10/3, 5 (written as the
    # shortest decimal text of the nearest double, as the CityJSON files' 1/3000 m scale gives).
    z = {130: Fraction(0), 140: Fraction(5, 3), 150: Fraction(10, 3), 160: Fraction(5)}
    tris = []
    for j in range(3):
        for i in range(3):
            x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
            a, b, c, d = P(x0, y0, z[x0]), P(x1, y0, z[x1]), P(x1, y1, z[x1]), P(x0, y1, z[x0])
            tris.append(face([a, b, c]))
            tris.append(face([a, c, d]))
    for t in tris:
        assert newell(t[0])[2] > 0
    return tris


def lamp_template():
    # Local coordinates: centred on the reference point in x and y, standing on it.
    h = Fraction(1, 10)
    def L(x, y, z): return (Fraction(x), Fraction(y), Fraction(z))
    f = [[[L(-h, -h, 0), L(-h, h, 0), L(h, h, 0), L(h, -h, 0)]],
         [[L(-h, -h, 0), L(h, -h, 0), L(h, -h, 4), L(-h, -h, 4)]],
         [[L(h, -h, 0), L(h, h, 0), L(h, h, 4), L(h, -h, 4)]],
         [[L(h, h, 0), L(-h, h, 0), L(-h, h, 4), L(h, h, 4)]],
         [[L(-h, h, 0), L(-h, -h, 0), L(-h, -h, 4), L(-h, h, 4)]],
         [[L(-h, -h, 4), L(h, -h, 4), L(h, h, 4), L(-h, h, 4)]]]
    check_closed('lamp', f)
    return f


IDENTITY = '1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1'

# (id, type, children, geometry): geometry is (kind, lod, faces) or ('instance', point).
OBJECTS = [
    ('gabled', 'Building', None, ('Solid', '2', gabled())),
    ('tower', 'Building', None, ('Solid', '2', tower())),
    ('stacked', 'Building', ['stacked-base', 'stacked-top'], None),
    ('overhang', 'Building', None, ('Solid', '2', overhang())),
    ('open', 'Building', None, ('Solid', '2', box_faces(90, 0, 0, 95, 5, 5, roof=False))),
    ('courtyard', 'Building', None, ('Solid', '1', courtyard())),
    ('slope', 'Building', None, ('Solid', '2', closed_box('slope', 140, 0, 1, 150, 10, 10))),
    ('terrain', 'TINRelief', None, ('Tin', '2', terrain())),
    ('lamp', 'CityFurniture', None, ('instance', P(125, 0, 0))),
    ('lamp2', 'CityFurniture', None, ('instance', P(125, 10, 0))),
    ('garden', 'LandUse', None, ('MultiSurface', '1', [face([P(0, 30, 0), P(10, 30, 0), P(10, 40, 0), P(0, 40, 0)])])),
    ('bridge', 'Bridge', None, ('Solid', '1', closed_box('bridge', 0, 50, 3, 20, 54, 4))),
]
PARTS = {
    'stacked-base': ('Solid', '2', closed_box('base', 50, 0, 0, 60, 10, 4)),
    'stacked-top': ('Solid', '2', closed_box('top', 50, 0, 4, 60, 10, 8)),
}


def num(c):
    # Exact decimal text of a Fraction with a power-of-ten denominator (millimetres at most); others
    # (the terrain's thirds) as the double nearest.
    f = Fraction(c)
    if (f * 1000).denominator != 1:
        return repr(float(f))  # thirds: the double nearest, in the shortest text that reads back to it
    s = f'{float(f):.3f}'.rstrip('0').rstrip('.')
    assert Fraction(s) == f, (c, s)
    return s


def pos_list(ring, v1):
    pts = ring + ring[:1]
    if v1:
        return ''.join(f'<gml:pos>{" ".join(num(c) for c in p)}</gml:pos>' for p in pts)
    return ('<gml:posList srsDimension="3">' + ' '.join(num(c) for p in pts for c in p)
            + '</gml:posList>')


def polygon(f, pid, v1, tag='gml:Polygon'):
    ident = f' gml:id="{pid}"' if pid else ''
    out = [f'<{tag}{ident}><gml:exterior><gml:LinearRing>{pos_list(f[0], v1)}</gml:LinearRing></gml:exterior>']
    for h in f[1:]:
        out.append(f'<gml:interior><gml:LinearRing>{pos_list(h, v1)}</gml:LinearRing></gml:interior>')
    out.append(f'</{tag}>')
    return ''.join(out)


def semantic(f, zmin):
    n = newell(f[0])
    if n[2] < 0 and n[0] == 0 and n[1] == 0:
        return 'GroundSurface' if f[0][0][2] == zmin else 'OuterFloorSurface'
    if n[2] > 0:
        return 'RoofSurface'
    return 'WallSurface'


def solid(oid, lod, faces, pfx, v1, lines, ind):
    lines.append(f'{ind}<{pfx}:lod{lod}Solid><gml:Solid><gml:exterior><gml:CompositeSurface>')
    if lod == '1':
        for k, f in enumerate(faces):
            lines.append(f'{ind}  <gml:surfaceMember>{polygon(f, f"{oid}-p{k}", v1)}</gml:surfaceMember>')
    else:
        for k in range(len(faces)):
            lines.append(f'{ind}  <gml:surfaceMember xlink:href="#{oid}-p{k}"/>')
    lines.append(f'{ind}</gml:CompositeSurface></gml:exterior></gml:Solid></{pfx}:lod{lod}Solid>')
    if lod != '1':
        zmin = min(p[2] for f in faces for p in f[0])
        for k, f in enumerate(faces):
            s = semantic(f, zmin)
            lines.append(f'{ind}<bldg:boundedBy><bldg:{s} gml:id="{oid}-s{k}"><bldg:lod{lod}MultiSurface>'
                         f'<gml:MultiSurface><gml:surfaceMember>{polygon(f, f"{oid}-p{k}", v1)}'
                         f'</gml:surfaceMember></gml:MultiSurface></bldg:lod{lod}MultiSurface>'
                         f'</bldg:{s}></bldg:boundedBy>')


def envelope(v1):
    pts = [p for _, _, _, g in OBJECTS if g and g[0] != 'instance' for f in g[2] for r in f for p in r]
    pts += [p for g in PARTS.values() for f in g[2] for r in f for p in r]
    lo = [min(p[i] for p in pts) for i in range(3)]
    hi = [max(p[i] for p in pts) for i in range(3)]
    dim = '' if v1 else ' srsDimension="3"'
    return (f'  <gml:boundedBy><gml:Envelope srsName="urn:ogc:def:crs:EPSG::28992"{dim}>'
            f'<gml:lowerCorner>{" ".join(num(c) for c in lo)}</gml:lowerCorner>'
            f'<gml:upperCorner>{" ".join(num(c) for c in hi)}</gml:upperCorner>'
            f'</gml:Envelope></gml:boundedBy>')


def write(path, v1, keep):
    ver = '1.0' if v1 else '2.0'
    ns = {'': f'http://www.opengis.net/citygml/{ver}',
          'bldg': f'http://www.opengis.net/citygml/building/{ver}',
          'dem': f'http://www.opengis.net/citygml/relief/{ver}',
          'frn': f'http://www.opengis.net/citygml/cityfurniture/{ver}',
          'luse': f'http://www.opengis.net/citygml/landuse/{ver}',
          'brid': f'http://www.opengis.net/citygml/bridge/{ver}',
          'gml': 'http://www.opengis.net/gml',
          'xlink': 'http://www.w3.org/1999/xlink'}
    if v1:
        del ns['brid']
    decl = ' '.join(f'xmlns{":" + k if k else ""}="{v}"' for k, v in ns.items())
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<!-- Generated by make_shapes_citygml.py: the objects of README.md, CityGML {ver}. -->',
             f'<CityModel {decl}>', envelope(v1)]
    for oid, otype, children, geom in OBJECTS:
        if oid not in keep:
            continue
        lines.append('  <cityObjectMember>')
        if otype == 'Building':
            lines.append(f'    <bldg:Building gml:id="{oid}">')
            if geom:
                solid(oid, geom[1], geom[2], 'bldg', v1, lines, '      ')
            for c in children or []:
                lines.append(f'      <bldg:consistsOfBuildingPart><bldg:BuildingPart gml:id="{c}">')
                g = PARTS[c]
                solid(c, g[1], g[2], 'bldg', v1, lines, '        ')
                lines.append('      </bldg:BuildingPart></bldg:consistsOfBuildingPart>')
            lines.append('    </bldg:Building>')
        elif otype == 'TINRelief':
            lines.append(f'    <dem:ReliefFeature gml:id="{oid}-feature"><dem:lod>2</dem:lod><dem:reliefComponent>')
            lines.append(f'      <dem:TINRelief gml:id="{oid}"><dem:lod>2</dem:lod><dem:tin>'
                         f'<gml:TriangulatedSurface gml:id="{oid}-surface"><gml:trianglePatches>')
            for f in geom[2]:
                lines.append('        ' + polygon(f, None, v1, 'gml:Triangle'))
            lines.append('      </gml:trianglePatches></gml:TriangulatedSurface></dem:tin></dem:TINRelief>')
            lines.append('    </dem:reliefComponent></dem:ReliefFeature>')
        elif otype == 'CityFurniture':
            lines.append(f'    <frn:CityFurniture gml:id="{oid}"><frn:lod1ImplicitRepresentation><ImplicitGeometry>')
            lines.append(f'      <transformationMatrix>{IDENTITY}</transformationMatrix>')
            if oid == 'lamp':
                lines.append('      <relativeGMLGeometry><gml:MultiSurface gml:id="lamp-template">')
                for k, f in enumerate(lamp_template()):
                    lines.append(f'        <gml:surfaceMember>{polygon(f, f"lamp-template-p{k}", v1)}</gml:surfaceMember>')
                lines.append('      </gml:MultiSurface></relativeGMLGeometry>')
            else:
                lines.append('      <relativeGMLGeometry xlink:href="#lamp-template"/>')
            p = geom[1]
            lines.append(f'      <referencePoint><gml:Point><gml:pos>{" ".join(num(c) for c in p)}</gml:pos></gml:Point></referencePoint>')
            lines.append('    </ImplicitGeometry></frn:lod1ImplicitRepresentation></frn:CityFurniture>')
        elif otype == 'LandUse':
            lines.append(f'    <luse:LandUse gml:id="{oid}"><luse:lod1MultiSurface><gml:MultiSurface>')
            for k, f in enumerate(geom[2]):
                lines.append(f'      <gml:surfaceMember>{polygon(f, f"{oid}-p{k}", v1)}</gml:surfaceMember>')
            lines.append('    </gml:MultiSurface></luse:lod1MultiSurface></luse:LandUse>')
        elif otype == 'Bridge':
            lines.append(f'    <brid:Bridge gml:id="{oid}">')
            solid(oid, geom[1], geom[2], 'brid', v1, lines, '      ')
            lines.append('    </brid:Bridge>')
        lines.append('  </cityObjectMember>')
    lines.append('</CityModel>')
    with open(path, 'w') as out:
        out.write('\n'.join(lines) + '\n')


write('shapes.gml', False, [o[0] for o in OBJECTS])
write('shapes_v1.gml', True, ['gabled', 'stacked'])
