#!/usr/bin/env python3
# Writes shapes.gml (CityGML 2.0) and shapes_v1.gml (CityGML 1.0: the gabled house and the stacked
# parts) with exactly the rings of shapes.city.json: the geometry comes from make_shapes_cityjson.py
# (the CityJSON files' generator, imported; run both from this folder). Rings: outer rings
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


# The geometry is shapes.city.json's, from its generator (one list of rings for both formats).
from make_shapes_cityjson import (P, box_faces, check_closed, closed_box, courtyard, face, gabled,  # noqa: E402
                                  lamp_template, newell, overhang, start_least, terrain, tower)


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
