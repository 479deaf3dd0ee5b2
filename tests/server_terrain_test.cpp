// A server whose cells follow terrain (issue 35, "Terrain"): the bands it sends in SceneInfo,
// read by the client's grid, and the poses it accepts per cell; a flat scene sends none.

#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "client/object_store.h"
#include "proto/scene_info.h"
#include "scenes/gltf_io.h"
#include "scenes/mesh.h"
#include "server/service.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"
#include "tests/terrain_test_util.h"

namespace vistream::server::test {
namespace {

// Two sheds on the ridge's valleys, served with 20 m cells under the name "ridge".
ServedScene& Ridge() {
  static ServedScene* scene = [] {
    const scenes::Scene flat = vistream::testing::TwoSheds();
    const std::string path = vistream::testing::ProcessTempDir() + "/ridge.glb";
    const absl::Status saved = scenes::SaveGltf(vistream::testing::OnTheRidge(flat), path);
    EXPECT_TRUE(saved.ok()) << saved;
    ServedSceneOptions o;
    o.scene = path;
    o.name = "ridge";
    o.cell_size = 20;
    o.threads = 2;
    o.idle_priority_masks = false;
    absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

TEST(ServerTerrain, SceneInfoCarriesEachCellsBandAndTheClientReadsThem) {
  const ServedScene& s = Ridge();
  ASSERT_TRUE(s.grid().has_bands());
  const v1::ViewcellGrid& g = s.scene_info().grid();
  ASSERT_EQ(static_cast<size_t>(g.band_z_size()), 2 * s.grid().CellCount());
  // The client's grid (proto/scene_info.h) is the server's: the same cells and bands.
  const absl::StatusOr<visibility::ViewcellGrid> info = GridFromSceneInfo(g);
  ASSERT_TRUE(info.ok()) << info.status();
  ASSERT_TRUE(info->has_bands());
  EXPECT_EQ(info->nx(), s.grid().nx());
  EXPECT_EQ(info->ny(), s.grid().ny());
  EXPECT_EQ(info->corner(), s.grid().corner());
  EXPECT_EQ(info->cell_size(), s.grid().cell_size());
  for (CellId c = 0; c < s.grid().CellCount(); ++c) {
    ASSERT_EQ(info->Band(c), s.grid().Band(c)) << c;
    ASSERT_EQ(info->CellBox(c).min, s.grid().CellBox(c).min) << c;
    ASSERT_EQ(info->CellBox(c).max, s.grid().CellBox(c).max) << c;
  }
  // The ridge's cells stand high: their bands are far above a flat grid's.
  const CellId top = *s.grid().CellAt({1, 1});
  EXPECT_EQ(info->CellAt({1, 1}), top);
  EXPECT_GT(info->Band(top).z0, 10.0);
  EXPECT_TRUE(info->InBand(top, s.grid().Band(top).z0 + 1.0));
  EXPECT_FALSE(info->InBand(top, 1.7));
  // A flat scene sends none: the bytes of SceneInfo are what they were before bands.
  EXPECT_EQ(City1().scene_info().grid().band_z_size(), 0);
  EXPECT_FALSE(GridFromSceneInfo(City1().scene_info().grid())->has_bands());
}

TEST(ServerTerrain, APoseIsInACellWhenInsideItsSquareAndItsBand) {
  ServerOptions options;
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(&Ridge(), options, nullptr);
  ASSERT_TRUE(server.ok()) << server.status();
  const visibility::ViewcellGrid& grid = Ridge().grid();
  const CellId top = *grid.CellAt({1, 1});
  {
    // On the ridge at 1.7 m above its ground: inside the cell's band, served.
    SessionStream c((*server)->address());
    c.Start(SessionStream::HelloFor("ridge"));
    c.SendCredit(uint64_t{1} << 40);
    const scenes::TerrainHeight ground(Ridge().scene());
    ASSERT_TRUE(c.SendPose({1, 1, ground.HeightAt({1, 1}) + 1.7}));
    EXPECT_TRUE(c.WaitFor([&](const client::SessionRecord& r) { return r.scene_info && r.CellComplete(top); }, kWait));
    EXPECT_EQ(c.Snapshot().info.grid().band_z_size(), static_cast<int>(2 * grid.CellCount()));
    EXPECT_TRUE(c.Finish().ok());
  }
  {
    // At a flat grid's eye height there, under the ridge's ground: refused, naming the cell.
    SessionStream c((*server)->address());
    c.Start(SessionStream::HelloFor("ridge"));
    ASSERT_TRUE(c.SendPose({1, 1, 1.7}));
    const grpc::Status st = c.AwaitEnd(kWait);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::OUT_OF_RANGE) << st.error_message();
    const visibility::CellCoord cc = grid.Coord(top);
    EXPECT_NE(st.error_message().find("outside viewcell " + std::to_string(cc.i) + "," + std::to_string(cc.j) +
                                      "'s band"),
              std::string::npos)
        << st.error_message();
  }
}

}  // namespace
}  // namespace vistream::server::test
