#include "client/session_stream.h"

#include <algorithm>

#include "client/connection.h"
#include "scenes/geometry_codec.h"

namespace vistream::client {

namespace v1 = vistream::v1;

namespace {
double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

double SessionRecord::CompletedAfter(uint32_t cell, double t) const {
  auto it = complete_s.find(cell);
  if (it == complete_s.end()) return -1.0;
  auto at = std::lower_bound(it->second.begin(), it->second.end(), t);
  return at == it->second.end() ? -1.0 : *at;
}

SessionStream::SessionStream(const std::string& address, const ChannelSecurity& security)
    : channel_(MakeChannel(address, security)), stub_(v1::Walkthrough::NewStub(channel_)), security_(security) {
  received_.completion_.on_complete = [this](uint32_t cell, double t) { received_.complete_s[cell].push_back(t); };
}

SessionStream::~SessionStream() {
  if (stream_ != nullptr && !finished_) {
    context_.TryCancel();
  }
  if (reader_.joinable()) reader_.join();
  if (stream_ != nullptr && !finished_) (void)stream_->Finish();
}

v1::Hello SessionStream::HelloFor(const std::string& scene, std::vector<uint32_t> held) {
  HelloSettings settings;
  settings.scene = scene;
  settings.held_objects = std::move(held);
  return MakeHello(settings);
}

void SessionStream::OpenStream() {
  channel_->WaitForConnected(std::chrono::system_clock::now() +
                             std::chrono::milliseconds(static_cast<int64_t>(kConnectTimeoutS * 1000)));
  Authorize(security_, &context_);
  stream_ = stub_->Session(&context_);
}

void SessionStream::Start(const v1::Hello& hello, bool read) {
  OpenStream();
  {
    std::lock_guard lock(mu_);
    for (uint32_t o : hello.held_objects()) {
      received_.held.insert(o);
      received_.completion_.Arrive(o, 0.0);
    }
  }
  v1::ClientMessage m;
  *m.mutable_hello() = hello;
  stream_->Write(m);
  if (read) reader_ = std::thread([this] { ReadLoop(); });
}

void SessionStream::HoldCluster(uint32_t cluster, uint32_t level, std::vector<uint32_t> objects) {
  std::lock_guard lock(mu_);
  received_.clusters[cluster] = level;
  received_.completion_.ArriveCluster(cluster, 0.0, level, objects);
}

void SessionStream::StartRaw(const v1::ClientMessage& first) {
  OpenStream();
  stream_->Write(first);
  reader_ = std::thread([this] { ReadLoop(); });
}

bool SessionStream::Send(const v1::ClientMessage& m) { return stream_->Write(m); }

bool SessionStream::SendPose(const glm::dvec3& position, const glm::dvec3& velocity) {
  return Send(PoseMessage(MakePose(position, velocity, 0.0, 0.0, time_s_ += 0.05)));
}

bool SessionStream::SendCredit(uint64_t bytes) { return Send(CreditMessage(bytes)); }

void SessionStream::ReadLoop() {
  v1::ServerMessage m;
  while (stream_->Read(&m)) {
    const double now = SteadySeconds();
    std::lock_guard lock(mu_);
    SessionRecord& r = received_;
    switch (m.body_case()) {
      case v1::ServerMessage::kSceneInfo:
        r.scene_info = true;
        r.info = m.scene_info();
        r.order.emplace_back('S', 0);
        break;
      case v1::ServerMessage::kPvs: {
        absl::StatusOr<proto::PvsList> list = lists_.Decode(m.pvs());
        if (!list.ok()) {
          r.bad_data = std::string(list.status().message());
          break;
        }
        const uint32_t cell = list->cell;
        r.pvs[cell] = list->objects;
        r.pvs_order.push_back(cell);
        r.order.emplace_back('P', cell);
        r.pvs_clusters[cell] = {list->cluster_ids, list->cluster_levels};
        r.completion_.SetList(cell, r.pvs[cell], now, list->levels, list->cluster_ids, list->cluster_levels);
        break;
      }
      case v1::ServerMessage::kCluster: {
        const v1::ClusterGeometry& g = m.cluster();
        r.clusters[g.cluster_id()] = g.level();
        ++r.cluster_levels;
        r.geometry_bytes += ChargedBytes(m);
        r.raw_geometry_bytes += scenes::RawMeshBytes(g.vertex_count(), g.index_count());
        r.order.emplace_back('C', g.cluster_id());
        if (keep_geometry_) r.cluster_geometry[g.cluster_id()] = g;
        const std::span<const uint32_t> objects(g.objects().data(), static_cast<size_t>(g.objects().size()));
        r.completion_.ArriveCluster(g.cluster_id(), now, g.level(), objects);
        break;
      }
      case v1::ServerMessage::kGeometry: {
        const uint32_t id = m.geometry().object_id();
        const CellCompletion::Object* before = r.completion_.Held(id);
        // Held already: at the same level, or named in Hello (whose level this record keeps not).
        if (before != nullptr ? before->level == m.geometry().level() : r.held.count(id) > 0) ++r.duplicates;
        r.held.insert(id);
        if (m.geometry().level() > 0) ++r.level_objects;
        r.geometry_bytes += ChargedBytes(m);
        r.raw_geometry_bytes += scenes::RawMeshBytes(m.geometry().vertex_count(), m.geometry().index_count());
        if (keep_geometry_) r.geometry[id] = m.geometry();
        r.order.emplace_back('G', id);
        r.completion_.Arrive(id, now, m.geometry().level());
        break;
      }
      case v1::ServerMessage::kEvict:
        for (uint32_t o : m.evict().object_ids()) {
          r.held.erase(o);
          r.evicted.push_back(o);
          r.completion_.Drop(o);
        }
        for (uint32_t c : m.evict().cluster_ids()) {
          r.clusters.erase(c);
          r.evicted_clusters.push_back(c);
          r.completion_.DropCluster(c);
        }
        r.order.emplace_back('E', 0);
        break;
      case v1::ServerMessage::kEpsilonMask:
        r.masks.push_back(m.epsilon_mask());
        r.mask_bytes += ChargedBytes(m);
        r.order.emplace_back('M', m.epsilon_mask().mask_id());
        break;
      case v1::ServerMessage::kEnd:  // WebSocket sessions only: a gRPC call ends with its status
      case v1::ServerMessage::BODY_NOT_SET:
        break;
    }
    cv_.notify_all();
    if (!r.bad_data.empty()) {
      context_.TryCancel();  // nothing after a list that does not decode can be trusted
      break;
    }
  }
  std::lock_guard lock(mu_);
  received_.ended = true;
  cv_.notify_all();
}

bool SessionStream::WaitFor(const std::function<bool(const SessionRecord&)>& done, double timeout_s) {
  std::unique_lock lock(mu_);
  return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                      [&] { return done(received_) || received_.ended; }) &&
         done(received_);
}

bool SessionStream::Ended() const {
  std::lock_guard lock(mu_);
  return received_.ended;
}

SessionRecord SessionStream::Snapshot() const {
  std::lock_guard lock(mu_);
  return received_;
}

grpc::Status SessionStream::Finish() {
  if (finished_) return status_;
  stream_->WritesDone();
  if (reader_.joinable()) reader_.join();
  status_ = stream_->Finish();
  finished_ = true;
  return status_;
}

grpc::Status SessionStream::AwaitEnd(double timeout_s) {
  if (finished_) return status_;
  {
    std::unique_lock lock(mu_);
    if (!cv_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return received_.ended; })) {
      lock.unlock();
      context_.TryCancel();
    }
  }
  if (reader_.joinable()) reader_.join();
  status_ = stream_->Finish();
  finished_ = true;
  return status_;
}

}  // namespace vistream::client
