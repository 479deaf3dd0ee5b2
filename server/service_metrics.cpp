#include "server/service_metrics.h"

#include <algorithm>

#include <absl/status/status.h>

namespace vistream::server {

ServiceMetrics::ServiceMetrics(MetricsRegistry* registry, const std::vector<std::string>& scenes)
    : registry_(registry) {
  MetricsRegistry& r = *registry_;
  for (const std::string& name : scenes) {
    const MetricLabels l = {{"scene", name}};
    PerScene p{
        r.GetGauge("vistream_sessions_active", "Sessions open, by the scene their Hello picked", l),
        r.GetCounter("vistream_bytes_sent_total", "Serialized server message bytes sent to clients", l),
        r.GetCounter("vistream_geometry_bytes_sent_total", "Encoded geometry bytes sent to clients", l),
        r.GetCounter("vistream_pvs_computations_total", "Viewcell PVSs computed (or looked up in a PVS file)", l),
        r.GetCounter("vistream_pvs_cache_hits_total",
                     "PVS requests answered from the cache or joined to a running computation", l),
        r.GetCounter("vistream_pvs_dropped_total", "Stale PVS requests dropped before they started", l),
        r.GetHistogram("vistream_pvs_compute_seconds", "Time one viewcell PVS computation took", SecondsBuckets(), l),
        r.GetHistogram("vistream_crossing_served_seconds",
                       "Time from a viewcell crossing until the new cells' PVS lists and geometry were sent",
                       SecondsBuckets(), l),
        r.GetCounter("vistream_late_cells_total", "Viewcells a client entered before their PVS and geometry were sent",
                     l),
        r.GetGauge("vistream_pvs_queue_length", "PVS requests waiting for a worker", l),
        r.GetGauge("vistream_send_queue_bytes", "Bytes queued for clients, not yet written", l),
        r.GetGauge("vistream_pvs_cache_bytes", "Bytes held by the PVS cache", l),
        r.GetCounter("vistream_pvs_store_hits_total", "Viewcell PVSs read from the shared PVS store, not computed", l),
    };
    scenes_.emplace(name, p);
    // The codes seen most, so that the family shows before the first session ends.
    r.GetCounter("vistream_sessions_ended_total", "Sessions ended, by scene and gRPC status code",
                 {{"scene", name}, {"code", "OK"}});
  }
  pre_hello_ = r.GetGauge("vistream_sessions_active", "Sessions open, by the scene their Hello picked",
                          {{"scene", ""}});
  r.GetCounter("vistream_sessions_refused_total", "Streams refused before a session started, by reason",
               {{"reason", "too_many"}});
  for (const char* transport : {"grpc", "websocket"}) {
    r.GetCounter("vistream_sessions_started_total", "Sessions admitted, by transport (grpc, websocket)",
                 {{"transport", transport}});
  }
  RegisterProcessMetrics(registry_);
}

ServiceMetrics::PerScene* ServiceMetrics::Find(const std::string& scene) {
  auto it = scenes_.find(scene);
  return it == scenes_.end() ? nullptr : &it->second;
}

void ServiceMetrics::Watch(std::function<v1::ServerStats()> stats) {
  registry_->AddCollector([this, stats = std::move(stats)] { Collect(stats()); });
}

void ServiceMetrics::Collect(const v1::ServerStats& stats) {
  std::map<std::string, uint64_t> queued;
  uint64_t pre_hello = 0;
  for (const v1::SessionStats& s : stats.sessions()) {
    if (s.scene().empty()) ++pre_hello;
    queued[s.scene()] += s.queued_bytes();
  }
  pre_hello_->Set(static_cast<double>(pre_hello));
  std::map<std::string, uint64_t> by_transport = {{"grpc", 0}, {"websocket", 0}};
  for (const v1::SessionStats& s : stats.sessions()) ++by_transport[s.transport()];
  for (const auto& [transport, n] : by_transport) {
    registry_->GetGauge("vistream_transport_sessions_active", "Sessions open, by transport (grpc, websocket)",
                        {{"transport", transport}})
        ->Set(static_cast<double>(n));
  }
  // Counters from cumulative figures: what grew since the last render.
  auto feed = [](Counter* c, uint64_t now, uint64_t* last) {
    if (now > *last) c->Add(static_cast<double>(now - *last));
    *last = std::max(*last, now);
  };
  for (const v1::SceneStats& s : stats.scenes()) {
    PerScene* p = Find(s.name());
    if (p == nullptr) continue;
    p->active->Set(static_cast<double>(s.sessions_active()));
    feed(p->bytes, s.bytes_sent(), &p->last_bytes);
    feed(p->geometry_bytes, s.geometry_bytes_sent(), &p->last_geometry);
    feed(p->computed, s.pvs_computed(), &p->last_computed);
    feed(p->cache_hits, s.pvs_cache_hits(), &p->last_hits);
    feed(p->dropped, s.pvs_dropped(), &p->last_dropped);
    p->pvs_queue->Set(static_cast<double>(s.pvs_queued()));
    p->cache_bytes->Set(static_cast<double>(s.cache_bytes()));
    p->send_queue->Set(static_cast<double>(queued[s.name()]));
    feed(p->store_hits, s.pvs_store_hits(), &p->last_store_hits);
  }
  if (stats.has_store()) {
    if (store_ == nullptr) {
      MetricsRegistry& r = *registry_;
      store_ = std::make_unique<StoreFamilies>(StoreFamilies{
          r.GetGauge("vistream_pvs_store_up", "1 while the shared PVS store (Redis) answers, else 0"),
          r.GetCounter("vistream_pvs_store_misses_total", "Store reads that found no entry"),
          r.GetCounter("vistream_pvs_store_bad_entries_total", "Store entries refused by their checks, recomputed"),
          r.GetCounter("vistream_pvs_store_unavailable_total",
                       "Store reads and writes skipped or failed: the store down or too slow"),
          r.GetCounter("vistream_pvs_store_writes_total", "Viewcell PVSs written back to the store"),
          r.GetCounter("vistream_pvs_store_writes_dropped_total", "Write-backs lost: queue full or store down"),
          r.GetCounter("vistream_pvs_store_outages_total", "Times the store went down"),
      });
    }
    const v1::StoreStats& st = stats.store();
    store_->up->Set(st.up() ? 1.0 : 0.0);
    feed(store_->misses, st.misses(), &store_->last_misses);
    feed(store_->bad, st.bad_entries(), &store_->last_bad);
    feed(store_->unavailable, st.unavailable(), &store_->last_unavailable);
    feed(store_->writes, st.writes(), &store_->last_writes);
    feed(store_->writes_dropped, st.writes_dropped(), &store_->last_dropped);
    feed(store_->outages, st.outages(), &store_->last_outages);
  }
}

void ServiceMetrics::AddSessionSeams(SessionSeams* seams) {
  seams->crossing_served = [this](const std::string& scene, double seconds) {
    if (PerScene* p = Find(scene)) p->crossing_s->Observe(seconds);
  };
  seams->late_cell = [this](const std::string& scene) {
    if (PerScene* p = Find(scene)) p->late->Add(1.0);
  };
}

std::function<void(double)> ServiceMetrics::PvsComputeObserver(const std::string& scene) {
  PerScene* p = Find(scene);
  if (p == nullptr) return nullptr;
  return [h = p->compute_s](double seconds) { h->Observe(seconds); };
}

void ServiceMetrics::SessionEnded(const std::string& scene, int grpc_code) {
  // gRPC's codes are absl's (same numbers, same names).
  const std::string code = absl::StatusCodeToString(static_cast<absl::StatusCode>(grpc_code));
  registry_->GetCounter("vistream_sessions_ended_total", "Sessions ended, by scene and gRPC status code",
                        {{"scene", scene}, {"code", code}})
      ->Add(1.0);
}

void ServiceMetrics::SessionStarted(const std::string& transport) {
  registry_->GetCounter("vistream_sessions_started_total", "Sessions admitted, by transport (grpc, websocket)",
                        {{"transport", transport}})
      ->Add(1.0);
}

void ServiceMetrics::SessionRefused(const std::string& reason) {
  registry_->GetCounter("vistream_sessions_refused_total", "Streams refused before a session started, by reason",
                        {{"reason", reason}})
      ->Add(1.0);
}

}  // namespace vistream::server
