#include "server/metrics.h"

#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <type_traits>

namespace vistream::server {
namespace {

// A programming error: says what is wrong and aborts (always, not only in debug builds).
[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "vistream metrics: %s\n", what.c_str());
  std::fflush(stderr);
  std::abort();
}

bool ValidName(std::string_view name, bool colon_allowed) {
  if (name.empty()) return false;
  for (size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool letter =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || (colon_allowed && c == ':');
    if (!letter && !(i > 0 && c >= '0' && c <= '9')) return false;
  }
  return true;
}

// The shortest text that reads back as `v` (Go's ParseFloat, which Prometheus uses, reads it).
std::string FormatValue(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  char buf[32];
  const std::to_chars_result r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// Help text: backslash and newline escaped.
void AppendHelp(std::string& out, std::string_view help) {
  for (char c : help) {
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
}

// `{a="x",b="y"}` (nothing when there are no labels and no `le`); values escaped: backslash,
// double quote, newline.
void AppendLabels(std::string& out, const MetricLabels& labels, const std::string* le = nullptr) {
  if (labels.empty() && le == nullptr) return;
  out += '{';
  bool first = true;
  auto append = [&](std::string_view name, std::string_view value) {
    if (!first) out += ',';
    first = false;
    out += name;
    out += "=\"";
    for (char c : value) {
      if (c == '\\') {
        out += "\\\\";
      } else if (c == '"') {
        out += "\\\"";
      } else if (c == '\n') {
        out += "\\n";
      } else {
        out += c;
      }
    }
    out += '"';
  };
  for (const auto& [name, value] : labels) append(name, value);
  if (le != nullptr) append("le", *le);
  out += '}';
}

// Labels sorted by name (one child per set, whatever order the caller wrote), checked.
MetricLabels Normalized(std::string_view metric, const MetricLabels& labels, bool histogram) {
  MetricLabels sorted = labels;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < sorted.size(); ++i) {
    const std::string& name = sorted[i].first;
    if (!ValidName(name, false) || name.starts_with("__")) {
      Fail("metric " + std::string(metric) + ": label name '" + name +
           "' must match [a-zA-Z_][a-zA-Z0-9_]* and not start with __");
    }
    if (histogram && name == "le")
      Fail("histogram " + std::string(metric) + ": the label name 'le' is reserved");
    if (i > 0 && sorted[i - 1].first == name)
      Fail("metric " + std::string(metric) + ": label '" + name + "' given twice");
  }
  return sorted;
}

template <typename T, typename Make>
T* Child(std::map<MetricLabels, std::unique_ptr<T>>& children, MetricLabels labels, Make make) {
  auto it = children.find(labels);
  if (it == children.end()) it = children.emplace(std::move(labels), make()).first;
  return it->second.get();
}

}  // namespace

void Counter::FailNegativeAdd(double v) {
  Fail("Counter::Add(" + FormatValue(v) + "): a counter only goes up (use a Gauge)");
}

Histogram::Histogram(std::vector<double> bounds) : bounds_(std::move(bounds)) {
  for (size_t i = 0; i < bounds_.size(); ++i) {
    if (!std::isfinite(bounds_[i]) || (i > 0 && !(bounds_[i - 1] < bounds_[i]))) {
      Fail("histogram bounds must be finite and strictly increasing; bound " + std::to_string(i) +
           " is " + FormatValue(bounds_[i]));
    }
  }
  counts_ = std::make_unique<std::atomic<uint64_t>[]>(bounds_.size() + 1);
  for (size_t i = 0; i <= bounds_.size(); ++i) counts_[i].store(0, std::memory_order_relaxed);
}

void Histogram::Observe(double v) {
  if (std::isnan(v)) return;
  // The first bound >= v (le is inclusive); past the last: the +Inf bucket.
  const size_t bucket = std::lower_bound(bounds_.begin(), bounds_.end(), v) - bounds_.begin();
  counts_[bucket].fetch_add(1, std::memory_order_relaxed);
  sum_.fetch_add(v, std::memory_order_relaxed);
}

Histogram::Snapshot Histogram::Read() const {
  Snapshot s;
  s.cumulative.resize(bounds_.size() + 1);
  uint64_t total = 0;
  for (size_t i = 0; i <= bounds_.size(); ++i) {
    total += counts_[i].load(std::memory_order_relaxed);
    s.cumulative[i] = total;
  }
  s.count = total;
  s.sum = sum_.load(std::memory_order_relaxed);
  return s;
}

MetricsRegistry::Family& MetricsRegistry::Declare(std::string_view name, std::string_view help,
                                                  Type type, const std::vector<double>* bounds) {
  static constexpr const char* kTypeNames[] = {"counter", "gauge", "histogram"};
  const std::string n(name);
  if (auto it = families_.find(name); it != families_.end()) {
    Family& f = it->second;
    if (f.type != type) {
      Fail("metric " + n + " declared as a " + kTypeNames[static_cast<int>(type)] + ", already a " +
           kTypeNames[static_cast<int>(f.type)]);
    }
    if (bounds != nullptr && *bounds != f.bounds)
      Fail("histogram " + n + " declared again with other buckets");
    return f;
  }
  if (!ValidName(name, true)) Fail("metric name '" + n + "' must match [a-zA-Z_:][a-zA-Z0-9_:]*");
  const bool total = name.ends_with("_total");
  if (type == Type::kCounter && !total) Fail("counter " + n + ": a counter's name ends in _total");
  if (type != Type::kCounter && total) Fail("metric " + n + ": only counters' names end in _total");
  // A histogram's series must not meet another family's name.
  static constexpr std::string_view kSuffixes[] = {"_bucket", "_sum", "_count"};
  for (std::string_view suffix : kSuffixes) {
    if (type == Type::kHistogram && families_.contains(n + std::string(suffix))) {
      Fail("histogram " + n + ": its series " + n + std::string(suffix) + " is already a metric");
    }
    if (name.ends_with(suffix)) {
      const std::string base(name.substr(0, name.size() - suffix.size()));
      auto h = families_.find(base);
      if (h != families_.end() && h->second.type == Type::kHistogram) {
        Fail("metric " + n + ": a series of the histogram " + base);
      }
    }
  }
  Family& f = families_[n];
  f.type = type;
  f.help = std::string(help);
  if (bounds != nullptr) f.bounds = *bounds;
  return f;
}

template <typename T>
T* MetricsRegistry::Get(std::string_view name, std::string_view help, const MetricLabels& labels, Type type,
                        const std::vector<double>* bounds, std::map<MetricLabels, std::unique_ptr<T>> Family::*children) {
  MetricLabels key = Normalized(name, labels, type == Type::kHistogram);
  std::lock_guard<std::mutex> lock(mu_);
  Family& f = Declare(name, help, type, bounds);
  return Child(f.*children, std::move(key), [&] {
    if constexpr (std::is_same_v<T, Histogram>) {
      return std::make_unique<Histogram>(f.bounds);
    } else {
      return std::make_unique<T>();
    }
  });
}

Counter* MetricsRegistry::GetCounter(std::string_view name, std::string_view help,
                                     const MetricLabels& labels) {
  return Get(name, help, labels, Type::kCounter, nullptr, &Family::counters);
}

Gauge* MetricsRegistry::GetGauge(std::string_view name, std::string_view help,
                                 const MetricLabels& labels) {
  return Get(name, help, labels, Type::kGauge, nullptr, &Family::gauges);
}

Histogram* MetricsRegistry::GetHistogram(std::string_view name, std::string_view help,
                                         std::vector<double> buckets, const MetricLabels& labels) {
  return Get(name, help, labels, Type::kHistogram, &buckets, &Family::histograms);
}

void MetricsRegistry::AddCollector(std::function<void()> collect) {
  std::lock_guard<std::mutex> lock(render_mu_);
  collectors_.push_back(std::move(collect));
}

std::string MetricsRegistry::Render() {
  std::lock_guard<std::mutex> render_lock(render_mu_);
  for (const std::function<void()>& collect : collectors_)
    collect();  // mu_ not held: they may Get...()

  std::lock_guard<std::mutex> lock(mu_);
  std::string out;
  for (const auto& [name, f] : families_) {
    out += "# HELP ";
    out += name;
    out += ' ';
    AppendHelp(out, f.help);
    out += "\n# TYPE ";
    out += name;
    out += f.type == Type::kCounter ? " counter\n"
           : f.type == Type::kGauge ? " gauge\n"
                                    : " histogram\n";
    auto sample = [&](std::string_view series, const MetricLabels& labels, const std::string& value,
                      const std::string* le = nullptr) {
      out += series;
      AppendLabels(out, labels, le);
      out += ' ';
      out += value;
      out += '\n';
    };
    for (const auto& [labels, c] : f.counters) sample(name, labels, FormatValue(c->value()));
    for (const auto& [labels, g] : f.gauges) sample(name, labels, FormatValue(g->value()));
    for (const auto& [labels, h] : f.histograms) {
      const Histogram::Snapshot s = h->Read();
      for (size_t i = 0; i < s.cumulative.size(); ++i) {
        const std::string le = i < f.bounds.size() ? FormatValue(f.bounds[i]) : "+Inf";
        sample(name + "_bucket", labels, std::to_string(s.cumulative[i]), &le);
      }
      sample(name + "_sum", labels, FormatValue(s.sum));
      sample(name + "_count", labels, std::to_string(s.count));
    }
  }
  return out;
}

uint64_t ProcessResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  uint64_t size_pages = 0;
  uint64_t resident_pages = 0;
  if (!(statm >> size_pages >> resident_pages)) return 0;
  const long page = sysconf(_SC_PAGESIZE);
  return page > 0 ? resident_pages * static_cast<uint64_t>(page) : 0;
}

void RegisterProcessMetrics(MetricsRegistry* registry) {
  Gauge* resident =
      registry->GetGauge("vistream_process_resident_memory_bytes",
                         "Resident memory of the server process in bytes (/proc/self/statm).");
  registry->AddCollector(
      [resident] { resident->Set(static_cast<double>(ProcessResidentBytes())); });
}

std::vector<double> SecondsBuckets() {
  return {0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30};
}

}  // namespace vistream::server
