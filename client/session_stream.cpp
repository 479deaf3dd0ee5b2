#include "client/session_stream.h"

#include <algorithm>

#include "client/connection.h"

namespace vistream::client {

namespace v1 = vistream::v1;

bool SessionRecord::CellComplete(uint32_t cell) const {
  auto it = pvs.find(cell);
  if (it == pvs.end()) return false;
  for (uint32_t o : it->second) {
    if (held.count(o) == 0) return false;
  }
  return true;
}

namespace {
double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

void SessionRecord::NoteCompletion(uint32_t cell, double now) { complete_s[cell].push_back(now); }

double SessionRecord::CompletedAfter(uint32_t cell, double t) const {
  auto it = complete_s.find(cell);
  if (it == complete_s.end()) return -1.0;
  auto at = std::lower_bound(it->second.begin(), it->second.end(), t);
  return at == it->second.end() ? -1.0 : *at;
}

SessionStream::SessionStream(const std::string& address, const ChannelSecurity& security)
    : channel_(MakeChannel(address, security)), stub_(v1::Walkthrough::NewStub(channel_)), security_(security) {}

SessionStream::~SessionStream() {
  if (stream_ != nullptr && !finished_) {
    context_.TryCancel();
  }
  if (reader_.joinable()) reader_.join();
  if (stream_ != nullptr && !finished_) (void)stream_->Finish();
}

v1::Hello SessionStream::HelloFor(const std::string& scene, std::vector<uint32_t> held) {
  v1::Hello h;
  h.set_scene(scene);
  h.set_protocol_version(v1::PROTOCOL_VERSION_CURRENT);
  h.mutable_held_objects()->Add(held.begin(), held.end());
  return h;
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
    for (uint32_t o : hello.held_objects()) received_.held.insert(o);
  }
  v1::ClientMessage m;
  *m.mutable_hello() = hello;
  stream_->Write(m);
  if (read) reader_ = std::thread([this] { ReadLoop(); });
}

void SessionStream::StartRaw(const v1::ClientMessage& first) {
  OpenStream();
  stream_->Write(first);
  reader_ = std::thread([this] { ReadLoop(); });
}

bool SessionStream::Send(const v1::ClientMessage& m) { return stream_->Write(m); }

bool SessionStream::SendPose(const glm::dvec3& position, const glm::dvec3& velocity) {
  v1::ClientMessage m;
  v1::Pose* p = m.mutable_pose();
  p->mutable_position()->set_x(position.x);
  p->mutable_position()->set_y(position.y);
  p->mutable_position()->set_z(position.z);
  p->mutable_velocity()->set_x(velocity.x);
  p->mutable_velocity()->set_y(velocity.y);
  p->mutable_velocity()->set_z(velocity.z);
  p->set_client_time_s(time_s_ += 0.05);
  return Send(m);
}

bool SessionStream::SendCredit(uint64_t bytes) {
  v1::ClientMessage m;
  m.mutable_credit()->set_bytes(bytes);
  return Send(m);
}

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
        const uint32_t cell = m.pvs().cell_id();
        r.pvs[cell].assign(m.pvs().object_ids().begin(), m.pvs().object_ids().end());
        r.pvs_order.push_back(cell);
        r.order.emplace_back('P', cell);
        uint32_t missing = 0;
        for (uint32_t o : r.pvs[cell]) {
          if (r.held.count(o) == 0) {
            ++missing;
            r.waiting_[o].push_back(cell);
          }
        }
        r.missing_[cell] = missing;
        if (missing == 0) r.NoteCompletion(cell, now);
        break;
      }
      case v1::ServerMessage::kGeometry: {
        const uint32_t id = m.geometry().object_id();
        if (!r.held.insert(id).second) ++r.duplicates;
        r.geometry_bytes += m.geometry().vertices().size() + m.geometry().indices().size();
        r.raw_geometry_bytes += uint64_t{m.geometry().vertex_count()} * 24 + uint64_t{m.geometry().index_count()} * 4;
        if (keep_geometry_) r.geometry[id] = m.geometry();
        r.order.emplace_back('G', id);
        if (auto it = r.waiting_.find(id); it != r.waiting_.end()) {
          for (uint32_t cell : it->second) {
            auto mi = r.missing_.find(cell);
            if (mi != r.missing_.end() && mi->second > 0 && --mi->second == 0) r.NoteCompletion(cell, now);
          }
          r.waiting_.erase(it);
        }
        break;
      }
      case v1::ServerMessage::kEvict:
        for (uint32_t o : m.evict().object_ids()) {
          r.held.erase(o);
          r.evicted.push_back(o);
        }
        r.order.emplace_back('E', 0);
        break;
      case v1::ServerMessage::kEpsilonMask:
        r.masks.push_back(m.epsilon_mask());
        r.mask_bytes += m.epsilon_mask().triangles().size();
        r.order.emplace_back('M', m.epsilon_mask().mask_id());
        break;
      case v1::ServerMessage::BODY_NOT_SET:
        break;
    }
    cv_.notify_all();
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
