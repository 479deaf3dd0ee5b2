#pragma once
// What the client's tests share: a small viewcell grid to feed the object store.

#include "proto/walkthrough.pb.h"

namespace vistream::client {

// Five cells of 10 m in a row (x from 0 to 50), a 2 m band from z = 0; 10 objects, 100 triangles.
inline vistream::v1::SceneInfo RowOfCells() {
  vistream::v1::SceneInfo info;
  info.set_name("row");
  info.set_object_count(10);
  info.set_triangle_count(100);
  vistream::v1::ViewcellGrid* grid = info.mutable_grid();
  grid->set_cell_size_m(10);
  grid->set_nx(5);
  grid->set_ny(1);
  grid->set_height_m(2);
  return info;
}

}  // namespace vistream::client
