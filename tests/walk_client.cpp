#include "tests/walk_client.h"

namespace vistream::testing {

namespace v1 = vistream::v1;

bool Received::CellComplete(uint32_t cell) const {
  auto it = pvs.find(cell);
  if (it == pvs.end()) return false;
  for (uint32_t o : it->second) {
    if (held.count(o) == 0) return false;
  }
  return true;
}

WalkClient::WalkClient(const std::string& address)
    : channel_(grpc::CreateChannel(address, grpc::InsecureChannelCredentials())),
      stub_(v1::Walkthrough::NewStub(channel_)) {}

WalkClient::~WalkClient() {
  if (stream_ != nullptr && !finished_) {
    context_.TryCancel();
  }
  if (reader_.joinable()) reader_.join();
  if (stream_ != nullptr && !finished_) (void)stream_->Finish();
}

v1::Hello WalkClient::HelloFor(const std::string& scene, std::vector<uint32_t> held) {
  v1::Hello h;
  h.set_scene(scene);
  h.set_protocol_version(v1::PROTOCOL_VERSION_CURRENT);
  h.mutable_held_objects()->Add(held.begin(), held.end());
  return h;
}

void WalkClient::Start(const v1::Hello& hello, bool read) {
  stream_ = stub_->Session(&context_);
  {
    std::lock_guard lock(mu_);
    for (uint32_t o : hello.held_objects()) received_.held.insert(o);
  }
  v1::ClientMessage m;
  *m.mutable_hello() = hello;
  stream_->Write(m);
  if (read) reader_ = std::thread([this] { ReadLoop(); });
}

void WalkClient::StartRaw(const v1::ClientMessage& first) {
  stream_ = stub_->Session(&context_);
  stream_->Write(first);
  reader_ = std::thread([this] { ReadLoop(); });
}

bool WalkClient::Send(const v1::ClientMessage& m) { return stream_->Write(m); }

bool WalkClient::SendPose(const glm::dvec3& position, const glm::dvec3& velocity) {
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

bool WalkClient::SendCredit(uint64_t bytes) {
  v1::ClientMessage m;
  m.mutable_credit()->set_bytes(bytes);
  return Send(m);
}

void WalkClient::ReadLoop() {
  v1::ServerMessage m;
  while (stream_->Read(&m)) {
    std::lock_guard lock(mu_);
    Received& r = received_;
    switch (m.body_case()) {
      case v1::ServerMessage::kSceneInfo:
        r.scene_info = true;
        r.info = m.scene_info();
        r.order.emplace_back('S', 0);
        break;
      case v1::ServerMessage::kPvs:
        r.pvs[m.pvs().cell_id()].assign(m.pvs().object_ids().begin(), m.pvs().object_ids().end());
        r.pvs_order.push_back(m.pvs().cell_id());
        r.order.emplace_back('P', m.pvs().cell_id());
        break;
      case v1::ServerMessage::kGeometry: {
        const uint32_t id = m.geometry().object_id();
        if (!r.held.insert(id).second) ++r.duplicates;
        r.geometry_bytes += m.geometry().vertices().size() + m.geometry().indices().size();
        r.geometry[id] = m.geometry();
        r.order.emplace_back('G', id);
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
        r.order.emplace_back('M', 0);
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

bool WalkClient::WaitFor(const std::function<bool(const Received&)>& done, double timeout_s) {
  std::unique_lock lock(mu_);
  return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s),
                      [&] { return done(received_) || received_.ended; }) &&
         done(received_);
}

Received WalkClient::Snapshot() const {
  std::lock_guard lock(mu_);
  return received_;
}

grpc::Status WalkClient::Finish() {
  if (finished_) return status_;
  stream_->WritesDone();
  if (reader_.joinable()) reader_.join();
  status_ = stream_->Finish();
  finished_ = true;
  return status_;
}

grpc::Status WalkClient::AwaitEnd(double timeout_s) {
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

}  // namespace vistream::testing
