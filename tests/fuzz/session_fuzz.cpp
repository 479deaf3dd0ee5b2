// libFuzzer target: a server session's client-message handler (Session::OnMessage and the
// writes it leads to) on untrusted bytes, as the gRPC edge feeds it.
//
// Input: one flags byte (bit 0: start with a valid Hello, bit 1: then a large Credit), then
// messages as [length byte][bytes]; bytes that are no ClientMessage end the session as the
// edge does. The scene is city1 with 50 m viewcells, its PVSs looked up in a file computed once
// (so each run is fast), ε-masks computed as the server would.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include <unistd.h>

#include "gl/pvs_backend.h"
#include "scenes/catalog.h"
#include "server/served_scene.h"
#include "server/session.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"
#include "visibility/pvs_file.h"

namespace {

using namespace vistream;  // NOLINT(google-build-using-namespace): a fuzz target's own file

server::ServedScene& Scene() {
  static server::ServedScene* scene = [] {
    const std::string path = (std::filesystem::temp_directory_path() / "vistream_session_fuzz.pvs").string();
    if (!std::filesystem::exists(path)) {
      absl::StatusOr<scenes::LoadedScene> s = scenes::LoadScene("city1");
      if (!s.ok()) std::abort();
      const visibility::ViewcellGrid grid = *visibility::ViewcellGrid::Create(s->scene.bounds, 50.0, 0.5, 2.0);
      const visibility::KdTree tree = visibility::KdTree::Build(s->scene);
      const visibility::PvsComputer computer(s->scene, tree);
      std::vector<visibility::CellId> cells(grid.CellCount());
      for (visibility::CellId c = 0; c < grid.CellCount(); ++c) cells[c] = c;
      visibility::GlobalPvs sets(grid.CellCount(), s->scene.objects.size());
      const absl::StatusOr<gl::PvsBackend> cpu = gl::PvsBackend::Create("cpu");
      if (!cpu.ok() || !gl::ComputeViewcellPvss(*cpu, computer, grid, cells, visibility::CellQueryOptions{}, {},
                                                "session fuzz PVS file",
                                                [&](visibility::CellId c, const visibility::PvsResult& r) {
                                                  sets.Assign(c, r.objects);
                                                  return absl::OkStatus();
                                                })
                            .ok()) {
        std::abort();
      }
      const std::string tmp = path + ".tmp" + std::to_string(::getpid());
      visibility::PvsProvenance provenance;
      provenance.strategy = "dual-ray-space cpu";
      std::ofstream(tmp, std::ios::binary)
          << visibility::EncodePvsFile(visibility::MakePvsFile(s->scene, grid, sets, provenance));
      std::filesystem::rename(tmp, path);
    }
    server::ServedSceneOptions o;
    o.scene = "city1";
    o.cell_size = 50.0;
    o.pvs_file = path;
    absl::StatusOr<std::unique_ptr<server::ServedScene>> s = server::ServedScene::Create(o);
    if (!s.ok()) {
      std::fprintf(stderr, "session_fuzz: %s\n", std::string(s.status().message()).c_str());
      std::abort();
    }
    return s->release();
  }();
  return *scene;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  server::ServedScene& scene = Scene();
  if (size == 0) return 0;
  server::SessionLimits limits;
  std::shared_ptr<server::Session> session = server::Session::Create(1, &scene, limits, nullptr, nullptr);
  double now = 1000.0;
  auto drain = [&] {
    for (int k = 0; k < 64; ++k) {
      if (!session->NextMessage().has_value()) break;
    }
  };
  const uint8_t flags = data[0];
  if (flags & 1) {
    vistream::v1::ClientMessage hello;
    hello.mutable_hello()->set_scene("city1");
    hello.mutable_hello()->set_protocol_version(vistream::v1::PROTOCOL_VERSION_CURRENT);
    hello.mutable_hello()->set_epsilon_masks(true);  // ε-masks along the fuzzed path
    if (!session->OnMessage(hello, now).ok()) std::abort();  // a valid Hello is accepted
    if (flags & 2) {
      vistream::v1::ClientMessage credit;
      credit.mutable_credit()->set_bytes(uint64_t{1} << 30);
      (void)session->OnMessage(credit, now);
    }
  }
  size_t at = 1;
  while (at < size) {
    const size_t n = std::min<size_t>(data[at], size - at - 1);
    vistream::v1::ClientMessage m;
    if (!m.ParseFromArray(data + at + 1, static_cast<int>(n))) break;  // the edge ends the session
    at += 1 + n;
    now += 0.01;
    if (!session->OnMessage(m, now).ok()) break;  // the session ends with that status
    drain();
  }
  // Let lookups and masks in flight land on the session, then end it as the edge does.
  std::this_thread::sleep_for(std::chrono::microseconds(200));
  drain();
  (void)session->Stats();
  session->End();
  return 0;
}
