#pragma once
// The server's metrics: counters, gauges and histograms held by a registry that renders them in
// Prometheus's text exposition format 0.0.4 (served over HTTP by server/metrics_http.h).
//
// Naming follows Prometheus's rules: names match [a-zA-Z_:][a-zA-Z0-9_:]*, values are in base
// units (seconds, bytes), counters end in `_total` and nothing else does. Breaking a rule is a
// programming error: the registry prints what is wrong and aborts.
//
// Updates are cheap and thread-safe (one relaxed atomic operation, a histogram two plus a
// search of its bounds): look a child up once with Get...() and keep the pointer, which stays
// valid for the registry's life.

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vistream::server {

// Label names and values of one child, e.g. {{"scene", "london"}, {"code", "OK"}}. Names match
// [a-zA-Z_][a-zA-Z0-9_]* and do not start with "__"; values are UTF-8 text, any characters.
// The order does not matter: {a, b} and {b, a} are the same child.
using MetricLabels = std::vector<std::pair<std::string, std::string>>;

// A value that only goes up (events, bytes); its name ends in `_total`.
class Counter {
 public:
  // Adds `v` >= 0 (a negative or NaN `v` is a programming error: aborts).
  void Add(double v = 1.0) {
    if (!(v >= 0)) FailNegativeAdd(v);
    value_.fetch_add(v, std::memory_order_relaxed);
  }
  double value() const { return value_.load(std::memory_order_relaxed); }

 private:
  [[noreturn]] static void FailNegativeAdd(double v);
  std::atomic<double> value_{0.0};
};

// A value that goes up and down (sessions open now, queue length, memory in bytes).
class Gauge {
 public:
  void Set(double v) { value_.store(v, std::memory_order_relaxed); }
  void Add(double v) { value_.fetch_add(v, std::memory_order_relaxed); }
  double value() const { return value_.load(std::memory_order_relaxed); }

 private:
  std::atomic<double> value_{0.0};
};

// Observations counted in buckets by upper bound (a value v falls in every bucket whose bound
// is >= v; rendered cumulative, with le="+Inf"), with their sum and count.
class Histogram {
 public:
  // `bounds`: finite, strictly increasing upper bounds (may be empty: +Inf only). Bad bounds
  // are a programming error: aborts.
  explicit Histogram(std::vector<double> bounds);

  // Counts `v` (a NaN is ignored: it belongs to no bucket and would poison the sum).
  void Observe(double v);

  struct Snapshot {
    std::vector<uint64_t> cumulative;  // per bound, then +Inf (== count)
    uint64_t count = 0;
    double sum = 0;
  };
  // The counts now; `cumulative.back() == count` even while other threads observe.
  Snapshot Read() const;
  const std::vector<double>& bounds() const { return bounds_; }

 private:
  std::vector<double> bounds_;
  std::unique_ptr<std::atomic<uint64_t>[]> counts_;  // per bucket, not cumulative; last: +Inf
  std::atomic<double> sum_{0.0};
};

class MetricsRegistry {
 public:
  MetricsRegistry() = default;
  MetricsRegistry(const MetricsRegistry&) = delete;
  MetricsRegistry& operator=(const MetricsRegistry&) = delete;

  // Declare the family `name` on first use (with `help`, one line of text; later calls keep the
  // first help) and return its child for `labels`, created on first use. The pointer stays
  // valid for the registry's life. Thread-safe; takes a lock and a map lookup, so keep the
  // pointer rather than calling these on every update.
  // Programming errors (abort, naming the metric): a name that breaks the rules above (a
  // counter not ending in `_total`, a gauge or histogram ending in it), one name declared with
  // two types or (histograms) two sets of bounds, a name that collides with a histogram's
  // `_bucket`/`_sum`/`_count` series, a bad or repeated label name, a histogram label `le`.
  Counter* GetCounter(std::string_view name, std::string_view help,
                      const MetricLabels& labels = {});
  Gauge* GetGauge(std::string_view name, std::string_view help, const MetricLabels& labels = {});
  // `buckets`: upper bounds as for Histogram, e.g. SecondsBuckets().
  Histogram* GetHistogram(std::string_view name, std::string_view help, std::vector<double> buckets,
                          const MetricLabels& labels = {});

  // Runs `collect` at the start of every Render(), e.g. to set gauges from live state. Collectors
  // run one at a time in the order added, on the rendering thread; they may call Get...() but
  // not AddCollector() or Render(). Whatever `collect` reads must outlive the registry's
  // renders (stop the HTTP server before destroying it).
  void AddCollector(std::function<void()> collect);

  // Every family in Prometheus's text exposition format 0.0.4: `# HELP` and `# TYPE` lines, then
  // one line per child (histograms: cumulative `_bucket{le="..."}` lines ending with
  // le="+Inf", then `_sum` and `_count`). Families sorted by name, children by their sorted
  // labels, so equal registries render equal text. Label values and help are escaped.
  // Thread-safe; renders run one at a time.
  std::string Render();

 private:
  enum class Type { kCounter, kGauge, kHistogram };
  struct Family {
    Type type;
    std::string help;
    std::vector<double> bounds;  // histograms
    std::map<MetricLabels, std::unique_ptr<Counter>> counters;
    std::map<MetricLabels, std::unique_ptr<Gauge>> gauges;
    std::map<MetricLabels, std::unique_ptr<Histogram>> histograms;
  };
  // The family `name` of `type`, declared if new (checking the rules); under mu_.
  Family& Declare(std::string_view name, std::string_view help, Type type,
                  const std::vector<double>* bounds);
  // The child for `labels` of the family `name` (declared as Declare does), one of `children`.
  template <typename T>
  T* Get(std::string_view name, std::string_view help, const MetricLabels& labels, Type type,
         const std::vector<double>* bounds, std::map<MetricLabels, std::unique_ptr<T>> Family::*children);

  std::mutex render_mu_;  // one Render() at a time; guards collectors_
  std::vector<std::function<void()>> collectors_;
  std::mutex mu_;  // guards families_ (not the children's values: they are atomic)
  std::map<std::string, Family, std::less<>> families_;
};

// Resident set size of this process in bytes (/proc/self/statm), 0 if unknown.
uint64_t ProcessResidentBytes();

// Adds a collector that sets the gauge `vistream_process_resident_memory_bytes` to
// ProcessResidentBytes() before every render.
void RegisterProcessMetrics(MetricsRegistry* registry);

// Histogram bounds in seconds for PVS compute times and crossing-to-delivered times:
// 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30.
std::vector<double> SecondsBuckets();

}  // namespace vistream::server
