#include "client/connection.h"

#include <algorithm>
#include <chrono>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>

#include "scenes/geometry_codec.h"

namespace vistream::client {

namespace v1 = vistream::v1;

std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address, const ChannelSecurity& security) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 30000);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 10000);
  args.SetMaxReceiveMessageSize(64 << 20);
  // Reconnect quickly after a restart: the session loop does its own back-off on top.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 250);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, ChannelCredentialsFor(security), args);
}

namespace {

std::chrono::system_clock::time_point After(double seconds) {
  return std::chrono::system_clock::now() + std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
}

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::chrono::steady_clock::time_point SteadyAt(double seconds) {
  return std::chrono::steady_clock::time_point(
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds)));
}

// Statuses after which reconnecting cannot help: the server refused this client's input.
bool Final(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::OUT_OF_RANGE:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::PERMISSION_DENIED:
    case grpc::StatusCode::UNAUTHENTICATED:
    case grpc::StatusCode::UNIMPLEMENTED:
    case grpc::StatusCode::DATA_LOSS:
      return true;
    default:
      return false;
  }
}

absl::Status ToAbsl(const grpc::Status& s) {
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
}

}  // namespace

absl::StatusOr<v1::ServerStats> Probe(const std::string& address, double timeout_s,
                                      const std::atomic<bool>* cancel, const ChannelSecurity& security) {
  std::shared_ptr<grpc::Channel> channel = MakeChannel(address, security);
  // Wait for a connection in short steps, so that a cancel is heard at once. The first failed
  // connect is looked at once: a TLS mismatch (DiagnoseTls) is final, no wait cures it.
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  bool diagnosed = false;
  auto tls_failure = [&](const std::string& why) {
    return absl::UnavailableError(absl::StrCat("cannot connect to the vistream server at ", address, ": ", why));
  };
  while (!channel->WaitForConnected(After(0.2)) && std::chrono::steady_clock::now() < until) {
    if (cancel != nullptr && cancel->load()) return absl::CancelledError("stopped while connecting");
    if (!diagnosed && channel->GetState(false) == GRPC_CHANNEL_TRANSIENT_FAILURE) {
      diagnosed = true;
      if (const std::string why = DiagnoseTls(address, security, 2.0); !why.empty()) return tls_failure(why);
    }
  }
  auto stub = v1::Walkthrough::NewStub(channel);
  grpc::ClientContext context;
  Authorize(security, &context);
  context.set_deadline(After(std::max(1.0, std::chrono::duration<double>(until - std::chrono::steady_clock::now()).count())));
  context.set_wait_for_ready(true);  // ride out a refused first connect; the deadline bounds it
  v1::ServerStats stats;
  const grpc::Status st = stub->GetStats(&context, v1::StatsRequest(), &stats);
  if (!st.ok()) {
    if (st.error_code() == grpc::StatusCode::UNAUTHENTICATED) return ExplainRefusal(ToAbsl(st), security, address);
    if (st.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED || st.error_code() == grpc::StatusCode::UNAVAILABLE) {
      // A TLS server may take the connection and then drop it (mutual TLS without a client
      // certificate): look again at the end.
      if (const std::string why = DiagnoseTls(address, security, 2.0); !why.empty()) return tls_failure(why);
      return absl::UnavailableError(absl::StrFormat("no vistream server answers at %s (waited %.0f s)", address,
                                                    timeout_s));
    }
    return absl::UnavailableError(
        absl::StrCat("the server at ", address, " does not answer as a vistream server: ", st.error_message()));
  }
  if (stats.protocol_version() != static_cast<uint32_t>(v1::PROTOCOL_VERSION_CURRENT)) {
    return absl::FailedPreconditionError(absl::StrCat("the server at ", address, " speaks protocol version ",
                                                      stats.protocol_version(), "; this client speaks version ",
                                                      static_cast<int>(v1::PROTOCOL_VERSION_CURRENT)));
  }
  return stats;
}

absl::StatusOr<std::string> PickScene(const v1::ServerStats& stats, const std::string& wanted,
                                      const std::string& address) {
  std::vector<std::string> served;
  for (const v1::SceneStats& s : stats.scenes()) served.push_back(s.name());
  if (served.empty()) served.push_back(stats.scene());  // a server of one scene that lists none
  if (wanted.empty()) {
    if (served.size() == 1) return served.front();
    return absl::NotFoundError(absl::StrCat("the server at ", address, " serves ", served.size(),
                                            " scenes: choose one with --scene (", absl::StrJoin(served, ", "), ")"));
  }
  if (std::find(served.begin(), served.end(), wanted) != served.end()) return wanted;
  return absl::NotFoundError(absl::StrCat("the server at ", address, " does not serve scene '", wanted,
                                          "'; it serves: ", absl::StrJoin(served, ", ")));
}

Connection::Connection(ConnectionOptions options)
    : options_(std::move(options)), channel_(MakeChannel(options_.address, options_.security)),
      stub_(v1::Walkthrough::NewStub(channel_)), credit_(options_.credit_window_bytes) {}

Connection::~Connection() { (void)Stop(); }

void Connection::Start() {
  if (thread_.joinable()) return;
  thread_ = std::thread([this] { Run(); });
}

void Connection::SetPose(const glm::dvec3& position, const glm::dvec3& velocity, double yaw_rad, double pitch_rad,
                         double client_time_s) {
  v1::Pose pose = MakePose(position, velocity, yaw_rad, pitch_rad, client_time_s);
  std::lock_guard lock(mu_);
  pose_ = std::move(pose);
  have_pose_ = true;
}

std::vector<Event> Connection::Take() {
  std::vector<Event> out;
  std::lock_guard lock(mu_);
  out.swap(inbox_);
  return out;
}

void Connection::Forget(const std::vector<uint32_t>& ids) {
  std::lock_guard lock(mu_);
  for (uint32_t id : ids) held_.erase(id);
}

absl::Status Connection::Stop() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lock(mu_);
  return final_status_;
}

void Connection::DropForTest() {
  std::lock_guard lock(mu_);
  if (context_ != nullptr) context_->TryCancel();
}

ConnectionStats Connection::stats() const {
  std::lock_guard lock(mu_);
  return stats_;
}

void Connection::Push(Event e) {
  std::lock_guard lock(mu_);
  inbox_.push_back(std::move(e));
}

void Connection::Run() {
  double backoff = 0.25;
  bool first = true;
  for (;;) {
    {
      std::lock_guard lock(mu_);
      if (stop_) break;
    }
    const bool was_first = first;
    first = false;
    const auto began = std::chrono::steady_clock::now();
    bool answered = false;
    const grpc::Status st = RunSession(&answered);
    std::unique_lock lock(mu_);
    if (answered && !was_first) ++stats_.reconnects;
    if (stop_) {
      // Our own close: OK, or whatever the server said last.
      if (final_status_.ok() && st.error_code() != grpc::StatusCode::CANCELLED) final_status_ = ToAbsl(st);
      break;
    }
    if (Final(st.error_code())) {
      final_status_ = ExplainRefusal(ToAbsl(st), options_.security, options_.address);
      inbox_.push_back(SessionEnded{final_status_});
      break;
    }
    // A dropped connection: try again after a back-off that resets once a session has lasted.
    if (std::chrono::steady_clock::now() - began > std::chrono::seconds(5)) backoff = 0.25;
    stats_.backoff_s = backoff;
    cv_.wait_for(lock, std::chrono::duration<double>(backoff), [&] { return stop_; });
    backoff = std::min(options_.max_backoff_s, 2.0 * backoff);
  }
  connected_ = false;
}

grpc::Status Connection::RunSession(bool* answered) {
  // Wait for a connection in short steps, so that Stop is heard at once.
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(options_.connect_timeout_s);
  while (!channel_->WaitForConnected(After(0.2)) && std::chrono::steady_clock::now() < until) {
    std::lock_guard lock(mu_);
    if (stop_) return grpc::Status(grpc::StatusCode::CANCELLED, "stopped");
  }
  grpc::ClientContext context;
  Authorize(options_.security, &context);
  auto stream = stub_->Session(&context);
  v1::ClientMessage hello, credit;
  {
    std::lock_guard lock(mu_);
    context_ = &context;
    reader_done_ = false;
    HelloSettings settings;
    settings.scene = options_.scene;
    settings.memory_budget_bytes = options_.memory_budget_bytes;
    settings.triangle_budget = options_.triangle_budget;
    settings.epsilon_masks = options_.epsilon_masks;
    settings.screen_error_px = options_.screen_error_px;
    settings.clusters = options_.clusters;
    for (const auto& [id, level] : held_clusters_) {
      settings.held_clusters.push_back(id);
      settings.held_cluster_levels.push_back(level);
    }
    settings.viewport_width_px = options_.viewport_width_px;
    settings.viewport_height_px = options_.viewport_height_px;
    settings.vertical_fov_rad = options_.vertical_fov_rad;
    for (const auto& [id, level] : held_) {
      settings.held_objects.push_back(id);
      settings.held_levels.push_back(level);
    }
    lists_.Clear();  // a new session's first list is whole
    hello = HelloMessage(settings);
    credit = CreditMessage(credit_.Open());
  }
  bool writing = stream->Write(hello) && stream->Write(credit);
  std::thread reader([&] { ReadLoop(stream.get()); });

  PoseCadence cadence(options_.pose_rate_hz);
  cadence.Restart(SteadySeconds());
  bool stopping = false;
  while (writing) {
    v1::ClientMessage pose, grant;
    {
      std::unique_lock lock(mu_);
      cv_.wait_until(lock, SteadyAt(cadence.next_s()),
                     [&] { return stop_ || reader_done_ || credit_.GrantDue(); });
      if (reader_done_) break;
      if (stop_) {
        stopping = true;
        break;
      }
      if (credit_.GrantDue()) grant = CreditMessage(credit_.TakeGrant());
      if (const double now = SteadySeconds(); cadence.Due(now)) {
        cadence.Sent(now);
        if (have_pose_) {
          pose = PoseMessage(pose_);
          ++stats_.poses_sent;
        }
      }
    }
    if (grant.has_credit()) writing = stream->Write(grant);
    if (writing && pose.has_pose()) writing = stream->Write(pose);
  }
  if (stopping) {
    stream->WritesDone();
    // A server that does not end the session soon after we closed our side is cut off.
    std::unique_lock lock(mu_);
    if (!cv_.wait_for(lock, std::chrono::seconds(5), [&] { return reader_done_; })) context.TryCancel();
  } else if (!writing) {
    context.TryCancel();  // the stream broke under a write: the reader ends with it
  }
  reader.join();
  *answered = connected_.load();
  const grpc::Status st = stream->Finish();
  {
    std::lock_guard lock(mu_);
    context_ = nullptr;
  }
  connected_ = false;
  return st;
}

void Connection::Fail(const std::string& why) {
  // Bad data from the server: nothing later can be trusted.
  std::lock_guard lock(mu_);
  final_status_ = absl::DataLossError(why);
  inbox_.push_back(SessionEnded{final_status_});
  stop_ = true;
  if (context_ != nullptr) context_->TryCancel();
}

void Connection::ReadLoop(grpc::ClientReaderWriter<v1::ClientMessage, v1::ServerMessage>* stream) {
  v1::ServerMessage m;
  while (stream->Read(&m)) {
    connected_ = true;  // the server answered this session
    const size_t bytes = m.ByteSizeLong();
    std::optional<Event> event;
    switch (m.body_case()) {
      case v1::ServerMessage::kSceneInfo:
        event = m.scene_info();
        break;
      case v1::ServerMessage::kPvs: {
        // Whole, with each object's level (a difference from the list before applied).
        absl::StatusOr<proto::PvsList> list = lists_.Decode(m.pvs());
        if (!list.ok()) {
          Fail(absl::StrCat("the server sent a malformed PVS list: ", list.status().message()));
          break;
        }
        v1::ViewcellPvs whole;
        whole.set_cell_id(list->cell);
        whole.set_compute_s(m.pvs().compute_s());
        whole.mutable_object_ids()->Add(list->objects.begin(), list->objects.end());
        whole.mutable_object_levels()->Add(list->levels.begin(), list->levels.end());
        whole.mutable_cluster_ids()->Add(list->cluster_ids.begin(), list->cluster_ids.end());
        whole.mutable_cluster_levels()->Add(list->cluster_levels.begin(), list->cluster_levels.end());
        event = std::move(whole);
        break;
      }
      case v1::ServerMessage::kEpsilonMask: {
        // The server charged the mask's triangle bytes to the credit: they are consumed, as
        // geometry is, or the credit would leak away and the session stall for good.
        const uint64_t mask_bytes = ChargedBytes(m);
        std::lock_guard lock(mu_);
        ++stats_.masks_received;
        stats_.mask_bytes += mask_bytes;
        credit_.Consume(mask_bytes);
        event = std::move(*m.mutable_epsilon_mask());
        break;
      }
      case v1::ServerMessage::kEvict: {
        std::lock_guard lock(mu_);
        for (uint32_t o : m.evict().object_ids()) held_.erase(o);
        for (uint32_t c : m.evict().cluster_ids()) held_clusters_.erase(c);
        event = m.evict();
        break;
      }
      case v1::ServerMessage::kGeometry: {
        const v1::ObjectGeometry& g = m.geometry();
        absl::StatusOr<DecodedObject> mesh = DecodeObjectGeometry(g);
        if (!mesh.ok()) {
          Fail(absl::StrCat("the server sent a malformed geometry message: ", mesh.status().message()));
          break;
        }
        ReceivedObject o;
        o.id = g.object_id();
        o.mesh = std::move(mesh->mesh);
        o.bounds_min = mesh->bounds_min;
        o.bounds_max = mesh->bounds_max;
        o.raw_bytes = mesh->raw_bytes;
        o.level = mesh->level;
        o.keeps_triangles = mesh->keeps_triangles;
        o.saved_bytes = mesh->saved_bytes;
        const uint64_t encoded = ChargedBytes(m);
        std::lock_guard lock(mu_);
        const auto [at, first] = held_.emplace(o.id, o.level);
        if (!first && at->second == o.level) ++stats_.duplicates;
        at->second = o.level;
        if (o.level > 0) {
          ++stats_.level_objects;
          stats_.level_bytes_saved += o.saved_bytes;
        }
        ++stats_.objects_received;
        stats_.geometry_bytes += encoded;
        credit_.Consume(encoded);
        event = std::move(o);
        break;
      }
      case v1::ServerMessage::kCluster: {
        absl::StatusOr<DecodedCluster> cluster = DecodeClusterGeometry(m.cluster());
        if (!cluster.ok()) {
          Fail(absl::StrCat("the server sent a malformed cluster message: ", cluster.status().message()));
          break;
        }
        const uint64_t encoded = ChargedBytes(m);
        std::lock_guard lock(mu_);
        held_clusters_[cluster->id] = cluster->level;
        ++stats_.cluster_levels;
        stats_.level_bytes_saved += cluster->saved_bytes;
        stats_.geometry_bytes += encoded;
        credit_.Consume(encoded);
        event = *std::move(cluster);
        break;
      }
      case v1::ServerMessage::kEnd:  // WebSocket sessions only: a gRPC call ends with its status
      case v1::ServerMessage::BODY_NOT_SET:
        break;
    }
    {
      std::lock_guard lock(mu_);
      stats_.bytes_received += bytes;
      if (event.has_value()) inbox_.push_back(std::move(*event));
    }
    cv_.notify_all();
  }
  {
    std::lock_guard lock(mu_);
    reader_done_ = true;
  }
  cv_.notify_all();
}

}  // namespace vistream::client
