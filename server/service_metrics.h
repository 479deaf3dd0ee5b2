#pragma once
// What vistream-server exports on /metrics (server/metrics_http.h; docs/deploying.md), named
// by Prometheus's rules (base units, `_total` counters, histograms), every family `vistream_`:
//
//   vistream_sessions_active{scene}                 sessions open (scene "" before their Hello)
//   vistream_sessions_ended_total{scene,code}       sessions ended, by gRPC status code name
//   vistream_bytes_sent_total{scene}                serialized ServerMessage bytes
//   vistream_geometry_bytes_sent_total{scene}       encoded geometry bytes among them
//   vistream_pvs_computations_total{scene}          PVSs computed (or looked up in a PVS file)
//   vistream_pvs_cache_hits_total{scene}            requests answered by the cache or a running job
//   vistream_pvs_dropped_total{scene}               stale requests dropped before they started
//   vistream_pvs_compute_seconds{scene}             histogram of one PVS computation's time
//   vistream_crossing_served_seconds{scene}         histogram: crossing to its new cells' PVS and
//                                                   geometry handed to the transport
//   vistream_late_cells_total{scene}                cells a client entered before they were served
//   vistream_pvs_queue_length{scene}                PVS requests waiting for a worker
//   vistream_send_queue_bytes{scene}                bytes queued for clients
//   vistream_pvs_cache_bytes{scene}                 the PVS cache's size
//   vistream_sessions_started_total{transport}     sessions admitted, by transport (grpc, websocket)
//   vistream_transport_sessions_active{transport}  sessions open, by transport
//   vistream_sessions_refused_total{reason}         calls refused before any work (unauthenticated,
//                                                   too_many, per_address, per_token, draining)
//   vistream_pvs_store_hits_total{scene}            PVSs read from the shared store, not computed
//   vistream_pvs_store_up                           1 while the shared PVS store answers, else 0
//   vistream_pvs_store_misses_total                 store reads that found no entry
//   vistream_pvs_store_bad_entries_total            store entries refused by their checks (recomputed)
//   vistream_pvs_store_unavailable_total            store reads and writes skipped or failed
//   vistream_pvs_store_writes_total                 PVSs written back to the store
//   vistream_pvs_store_writes_dropped_total         write-backs lost (queue full, store down)
//   vistream_pvs_store_outages_total                times the store went down
//   (the store families only with a store configured)
//   vistream_process_resident_memory_bytes          the process's resident memory

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "proto/walkthrough.pb.h"
#include "server/metrics.h"
#include "server/session.h"

namespace vistream::server {

class ServiceMetrics {
 public:
  // Declares every family above in `registry` (not owned) for `scenes` (their names).
  ServiceMetrics(MetricsRegistry* registry, const std::vector<std::string>& scenes);

  // Reads the server's live figures through `stats` (WalkthroughService::Stats,
  // server/service.h) before every render; what it reads must outlive the registry's renders.
  // A function rather than the service, so that the service, which reports to these metrics,
  // and the metrics do not include each other.
  void Watch(std::function<vistream::v1::ServerStats()> stats);
  // The session seams that report crossings served and late cells.
  void AddSessionSeams(SessionSeams* seams);
  // Observes each PVS computation of `scene`'s scheduler (PvsScheduler::SetComputeObserver).
  std::function<void(double)> PvsComputeObserver(const std::string& scene);
  void SessionEnded(const std::string& scene, int grpc_code);
  // A session was admitted over `transport` ("grpc", "websocket").
  void SessionStarted(const std::string& transport);
  // `reason`: a short word (draining, too_many, unauthenticated, per_address, per_token, ...).
  void SessionRefused(const std::string& reason);

 private:
  struct PerScene {
    Gauge* active;
    Counter* bytes;
    Counter* geometry_bytes;
    Counter* computed;
    Counter* cache_hits;
    Counter* dropped;
    Histogram* compute_s;
    Histogram* crossing_s;
    Counter* late;
    Gauge* pvs_queue;
    Gauge* send_queue;
    Gauge* cache_bytes;
    Counter* store_hits;
    // What the counters fed from cumulative figures last saw.
    uint64_t last_bytes = 0, last_geometry = 0, last_computed = 0, last_hits = 0, last_dropped = 0,
             last_store_hits = 0;
  };
  PerScene* Find(const std::string& scene);
  void Collect(const vistream::v1::ServerStats& stats);

  struct StoreFamilies {
    Gauge* up;
    Counter *misses, *bad, *unavailable, *writes, *writes_dropped, *outages;
    uint64_t last_misses = 0, last_bad = 0, last_unavailable = 0, last_writes = 0, last_dropped = 0,
             last_outages = 0;
  };

  MetricsRegistry* registry_;
  std::unique_ptr<StoreFamilies> store_;    // declared at the first stats naming a store
  std::map<std::string, PerScene> scenes_;  // fixed after construction: read without a lock
  Gauge* pre_hello_;                        // sessions_active{scene=""}
};

}  // namespace vistream::server
