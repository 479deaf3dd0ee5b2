// The metrics registry (server/metrics.h): Prometheus's text exposition format, exact to the
// line, checked by Prometheus's own promtool; and its HTTP endpoint (server/metrics_http.h) on
// loopback: /metrics, /healthz, 404s and the errors of a bad or busy address.
#include "server/metrics.h"

#include <gtest/gtest.h>
#include <httplib.h>
#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/session_stream.h"
#include "server/metrics_http.h"
#include "tests/server_process_util.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

// `text`'s lines that start with `prefix`.
std::vector<std::string> Lines(const std::string& text, const std::string& prefix) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(start, end - start);
    if (line.starts_with(prefix)) out.push_back(line);
    start = end + 1;
  }
  return out;
}

TEST(Metrics, RendersHelpTypeLabelsAndCumulativeBucketsExactly) {
  MetricsRegistry r;
  r.GetCounter("vistream_bytes_sent_total", "Bytes sent to clients.", {{"scene", "london"}})
      ->Add(1536);
  // Backslash, double quote and newline are escaped in label values; a later help is ignored.
  r.GetCounter("vistream_bytes_sent_total", "other help", {{"scene", "a \"b\" \\ c\nd"}})->Add(2);
  r.GetGauge("vistream_sessions_active", "Sessions open now.")->Set(3);
  Histogram* h =
      r.GetHistogram("vistream_pvs_compute_seconds", "PVS compute time\\cell,\nin seconds.",
                     {0.1, 1, 10}, {{"scene", "london"}});
  // 1.0 falls in le="1": bounds are inclusive.
  for (double v : {0.0625, 0.5, 1.0, 40.5}) h->Observe(v);
  const std::string expected = R"exp(# HELP vistream_bytes_sent_total Bytes sent to clients.
# TYPE vistream_bytes_sent_total counter
vistream_bytes_sent_total{scene="a \"b\" \\ c\nd"} 2
vistream_bytes_sent_total{scene="london"} 1536
# HELP vistream_pvs_compute_seconds PVS compute time\\cell,\nin seconds.
# TYPE vistream_pvs_compute_seconds histogram
vistream_pvs_compute_seconds_bucket{scene="london",le="0.1"} 1
vistream_pvs_compute_seconds_bucket{scene="london",le="1"} 3
vistream_pvs_compute_seconds_bucket{scene="london",le="10"} 3
vistream_pvs_compute_seconds_bucket{scene="london",le="+Inf"} 4
vistream_pvs_compute_seconds_sum{scene="london"} 42.0625
vistream_pvs_compute_seconds_count{scene="london"} 4
# HELP vistream_sessions_active Sessions open now.
# TYPE vistream_sessions_active gauge
vistream_sessions_active 3
)exp";
  EXPECT_EQ(r.Render(), expected);
  EXPECT_EQ(r.Render(), expected);  // rendering changes nothing
}

TEST(Metrics, OneChildPerLabelSetWhateverTheOrderAndLabelsRenderSortedByName) {
  MetricsRegistry r;
  Counter* a = r.GetCounter("vistream_sessions_ended_total", "Sessions ended.",
                            {{"scene", "x"}, {"code", "OK"}});
  Counter* b = r.GetCounter("vistream_sessions_ended_total", "Sessions ended.",
                            {{"code", "OK"}, {"scene", "x"}});
  Counter* c = r.GetCounter("vistream_sessions_ended_total", "Sessions ended.",
                            {{"code", "CANCELLED"}, {"scene", "x"}});
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  a->Add();
  b->Add(0.5);
  EXPECT_EQ(a->value(), 1.5);
  EXPECT_EQ(
      Lines(r.Render(), "vistream_sessions_ended_total"),
      (std::vector<std::string>{R"(vistream_sessions_ended_total{code="CANCELLED",scene="x"} 0)",
                                R"(vistream_sessions_ended_total{code="OK",scene="x"} 1.5)"}));
}

TEST(Metrics, GaugesGoUpAndDownAndRenderSpecialValues) {
  MetricsRegistry r;
  Gauge* g = r.GetGauge("vistream_queue_length", "Requests waiting.");
  g->Set(5);
  g->Add(-7);
  EXPECT_EQ(g->value(), -2);
  r.GetGauge("vistream_big", "A large value.")->Set(1e300);
  r.GetGauge("vistream_inf", "An infinite value.")->Set(std::numeric_limits<double>::infinity());
  r.GetGauge("vistream_nan", "Not a number.")->Set(std::nan(""));
  const std::string text = r.Render();
  EXPECT_EQ(Lines(text, "vistream_queue_length "),
            std::vector<std::string>{"vistream_queue_length -2"});
  EXPECT_EQ(Lines(text, "vistream_big "), std::vector<std::string>{"vistream_big 1e+300"});
  EXPECT_EQ(Lines(text, "vistream_inf "), std::vector<std::string>{"vistream_inf +Inf"});
  EXPECT_EQ(Lines(text, "vistream_nan "), std::vector<std::string>{"vistream_nan NaN"});
}

TEST(Metrics, HistogramWithoutBoundsHasOnlyInfAndIgnoresNan) {
  MetricsRegistry r;
  Histogram* h = r.GetHistogram("vistream_wait_seconds", "Waits.", {});
  h->Observe(2);
  h->Observe(std::nan(""));
  h->Observe(-1);
  EXPECT_EQ(
      Lines(r.Render(), "vistream_wait_seconds"),
      (std::vector<std::string>{R"(vistream_wait_seconds_bucket{le="+Inf"} 2)",
                                "vistream_wait_seconds_sum 1", "vistream_wait_seconds_count 2"}));
  EXPECT_EQ(h, r.GetHistogram("vistream_wait_seconds", "Waits.", {}));
}

TEST(Metrics, SecondsBucketsSpanFiveMillisecondsToThirtySeconds) {
  const std::vector<double> b = SecondsBuckets();
  ASSERT_FALSE(b.empty());
  EXPECT_EQ(b.front(), 0.005);
  EXPECT_EQ(b.back(), 30);
  for (size_t i = 1; i < b.size(); ++i) EXPECT_LT(b[i - 1], b[i]);
}

TEST(Metrics, CollectorsRunBeforeEveryRender) {
  MetricsRegistry r;
  int runs = 0;
  r.AddCollector([&] {
    ++runs;
    // A collector may declare and look up metrics.
    r.GetGauge("vistream_sessions_active", "Sessions open now.", {{"scene", "london"}})
        ->Set(runs * 10);
  });
  EXPECT_EQ(Lines(r.Render(), "vistream_sessions_active{"),
            std::vector<std::string>{R"(vistream_sessions_active{scene="london"} 10)"});
  EXPECT_EQ(Lines(r.Render(), "vistream_sessions_active{"),
            std::vector<std::string>{R"(vistream_sessions_active{scene="london"} 20)"});
  EXPECT_EQ(runs, 2);
}

TEST(Metrics, ProcessResidentMemoryIsMeasuredAndGrowsWithTouchedMemory) {
  const uint64_t before = ProcessResidentBytes();
  EXPECT_GT(before, uint64_t{1} << 20);
  std::vector<char> block(64 << 20, 1);               // written, so resident
  asm volatile("" : : "r"(block.data()) : "memory");  // and not optimised away
  EXPECT_GT(ProcessResidentBytes(), before + (48u << 20));
  EXPECT_EQ(block[block.size() / 2], 1);

  MetricsRegistry r;
  RegisterProcessMetrics(&r);
  const std::vector<std::string> line =
      Lines(r.Render(), "vistream_process_resident_memory_bytes ");
  ASSERT_EQ(line.size(), 1u);
  EXPECT_GT(std::stod(line[0].substr(line[0].find(' ') + 1)), 64.0 * (1 << 20));
}

TEST(Metrics, ConcurrentUpdatesFromSeveralThreadsAllCount) {
  MetricsRegistry r;
  constexpr int kThreads = 8;
  constexpr int kEach = 20000;
  std::atomic<bool> done{false};
  std::atomic<int> renders{0};
  // A scraper renders all the while; every histogram's +Inf bucket equals its count.
  std::thread scraper([&] {
    while (!done.load()) {
      const std::string text = r.Render();
      const std::vector<std::string> inf = Lines(text, R"(vistream_t_seconds_bucket{le="+Inf"} )");
      const std::vector<std::string> count = Lines(text, "vistream_t_seconds_count ");
      if (!inf.empty() && !count.empty()) {
        EXPECT_EQ(inf[0].substr(inf[0].rfind(' ')), count[0].substr(count[0].rfind(' ')));
      }
      renders.fetch_add(1);
    }
  });
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&r, &renders, t] {
      // Every thread looks its children up itself, the first ones at the same time.
      Counter* c = r.GetCounter("vistream_t_total", "Events.", {{"scene", "london"}});
      Counter* mine =
          r.GetCounter("vistream_t_total", "Events.", {{"scene", "t" + std::to_string(t)}});
      Gauge* g = r.GetGauge("vistream_t_open", "Open.");
      Histogram* h = r.GetHistogram("vistream_t_seconds", "Times.", {1.0});
      // Update only once the scraper is rendering, so that its renders meet the updates.
      while (renders.load() == 0) std::this_thread::yield();
      for (int i = 0; i < kEach; ++i) {
        c->Add();
        mine->Add(2);
        g->Add(i % 2 == 0 ? 3 : -1);
        h->Observe(i % 2 == 0 ? 0.5 : 5.0);
      }
    });
  }
  for (std::thread& t : threads) t.join();
  done.store(true);
  scraper.join();
  EXPECT_GT(renders.load(), 0);

  EXPECT_EQ(r.GetCounter("vistream_t_total", "Events.", {{"scene", "london"}})->value(),
            kThreads * kEach);
  for (int t = 0; t < kThreads; ++t) {
    EXPECT_EQ(
        r.GetCounter("vistream_t_total", "Events.", {{"scene", "t" + std::to_string(t)}})->value(),
        2 * kEach);
  }
  EXPECT_EQ(r.GetGauge("vistream_t_open", "Open.")->value(), kThreads * kEach);
  const Histogram::Snapshot s = r.GetHistogram("vistream_t_seconds", "Times.", {1.0})->Read();
  EXPECT_EQ(s.count, uint64_t{kThreads} * kEach);
  EXPECT_EQ(s.cumulative, (std::vector<uint64_t>{kThreads * kEach / 2, kThreads * kEach}));
  EXPECT_EQ(s.sum, kThreads * kEach / 2 * 5.5);
}

// Breaking Prometheus's rules is a programming error: the process says what and aborts.
class MetricsDeathTest : public ::testing::Test {
 protected:
  void SetUp() override { GTEST_FLAG_SET(death_test_style, "threadsafe"); }
  MetricsRegistry r;
};

TEST_F(MetricsDeathTest, CountersEndInTotal) {
  EXPECT_DEATH(r.GetCounter("vistream_bytes_sent", "Bytes."),
               "counter vistream_bytes_sent: a counter's name ends in _total");
}

TEST_F(MetricsDeathTest, OnlyCountersEndInTotal) {
  EXPECT_DEATH(r.GetGauge("vistream_open_total", "Open."), "only counters' names end in _total");
  EXPECT_DEATH(r.GetHistogram("vistream_wait_total", "Waits.", {1}),
               "only counters' names end in _total");
}

TEST_F(MetricsDeathTest, NamesFollowPrometheusRules) {
  for (const char* name : {"", "1abc", "vistream-sessions", "vistream sessions", "vistream_é"}) {
    EXPECT_DEATH(r.GetGauge(name, "Help."), "must match \\[a-zA-Z_:\\]\\[a-zA-Z0-9_:\\]\\*")
        << name;
  }
}

TEST_F(MetricsDeathTest, OneNameHasOneTypeAndOneSetOfBuckets) {
  r.GetCounter("vistream_x_total", "X.");
  EXPECT_DEATH(r.GetGauge("vistream_x_total", "X."),
               "metric vistream_x_total declared as a gauge, already a counter");
  r.GetHistogram("vistream_y_seconds", "Y.", {1, 2});
  EXPECT_DEATH(r.GetHistogram("vistream_y_seconds", "Y.", {1, 3}),
               "declared again with other buckets");
}

TEST_F(MetricsDeathTest, HistogramSeriesDoNotMeetOtherMetrics) {
  r.GetHistogram("vistream_y_seconds", "Y.", {1});
  EXPECT_DEATH(r.GetGauge("vistream_y_seconds_count", "Y."),
               "a series of the histogram vistream_y_seconds");
  r.GetGauge("vistream_z_seconds_sum", "Z.");
  EXPECT_DEATH(r.GetHistogram("vistream_z_seconds", "Z.", {1}),
               "its series vistream_z_seconds_sum is already a metric");
}

TEST_F(MetricsDeathTest, LabelNamesFollowPrometheusRules) {
  EXPECT_DEATH(r.GetGauge("vistream_g", "G.", {{"__name", "x"}}), "label name '__name'");
  EXPECT_DEATH(r.GetGauge("vistream_g", "G.", {{"a-b", "x"}}), "label name 'a-b'");
  EXPECT_DEATH(r.GetGauge("vistream_g", "G.", {{"scene", "x"}, {"scene", "y"}}),
               "label 'scene' given twice");
  EXPECT_DEATH(r.GetHistogram("vistream_h_seconds", "H.", {1}, {{"le", "1"}}),
               "the label name 'le' is reserved");
}

TEST_F(MetricsDeathTest, HistogramBoundsAreFiniteAndIncrease) {
  EXPECT_DEATH(r.GetHistogram("vistream_h_seconds", "H.", {1, 1}),
               "strictly increasing; bound 1 is 1");
  EXPECT_DEATH(r.GetHistogram("vistream_h_seconds", "H.", {2, 1}),
               "strictly increasing; bound 1 is 1");
  EXPECT_DEATH(
      r.GetHistogram("vistream_h_seconds", "H.", {1, std::numeric_limits<double>::infinity()}),
      "bound 1 is \\+Inf");
  EXPECT_DEATH(r.GetHistogram("vistream_h_seconds", "H.", {std::nan("")}), "bound 0 is NaN");
}

TEST_F(MetricsDeathTest, CountersOnlyGoUp) {
  Counter* c = r.GetCounter("vistream_c_total", "C.");
  EXPECT_DEATH(c->Add(-1), "a counter only goes up");
  EXPECT_DEATH(c->Add(std::nan("")), "a counter only goes up");
}

// promtool (Debian prometheus) reads an exposition on its standard input: its exit code and
// everything it printed.
std::pair<int, std::string> Promtool(const std::string& exposition) {
  const std::string file = testing::ProcessTempDir() + "/exposition.txt";
  std::ofstream(file) << exposition;
  std::string out;
  std::FILE* p =
      popen((std::string(VISTREAM_PROMTOOL " check metrics < ") + file + " 2>&1").c_str(), "r");
  if (p == nullptr) return {-1, "popen failed"};
  char buf[1024];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

// Fails (not skips) without promtool: the check is part of what the server promises.
void RequirePromtool() {
  const std::string path = VISTREAM_PROMTOOL;
  ASSERT_TRUE(path.find("NOTFOUND") == std::string::npos && std::ifstream(path).good())
      << "promtool not found (CMake looked for it at configure time: '" << path
      << "'): install Debian's prometheus package (./vistream.sh does) and configure again";
}

TEST(MetricsPromtool, PassesARenderedRegistryWithEveryTypeAndLabels) {
  ASSERT_NO_FATAL_FAILURE(RequirePromtool());
  MetricsRegistry r;
  RegisterProcessMetrics(&r);
  for (const char* scene : {"london", "monaco", "quote \" backslash \\ newline \n end"}) {
    r.GetGauge("vistream_sessions_active", "Sessions open now.", {{"scene", scene}})->Set(2);
    r.GetCounter("vistream_sessions_ended_total", "Sessions ended, by status code.",
                 {{"scene", scene}, {"code", "OK"}})
        ->Add(3);
    r.GetCounter("vistream_bytes_sent_total", "Bytes sent to clients.", {{"scene", scene}})
        ->Add(1e9);
    Histogram* h = r.GetHistogram("vistream_pvs_compute_seconds",
                                  "Time to compute one cell's PVS, in seconds.", SecondsBuckets(),
                                  {{"scene", scene}});
    for (double v : {0.001, 0.02, 0.3, 4.0, 50.0}) h->Observe(v);
  }
  r.GetCounter("vistream_pvs_cache_hits_total",
               "PVS requests served from the cache.\nSecond line \\ of help.")
      ->Add();
  const std::string text = r.Render();
  const auto [rc, out] = Promtool(text);
  EXPECT_EQ(rc, 0) << out << "\non:\n" << text;
  EXPECT_EQ(out, "") << "on:\n" << text;
}

TEST(MetricsPromtool, FlagsABadExposition) {
  ASSERT_NO_FATAL_FAILURE(RequirePromtool());
  {  // A rule broken: promtool lints it.
    const auto [rc, out] = Promtool(
        "# HELP sessions_ended Sessions.\n# TYPE sessions_ended counter\nsessions_ended 3\n");
    EXPECT_NE(rc, 0) << out;
    EXPECT_NE(out.find("sessions_ended counter metrics should have \"_total\" suffix"),
              std::string::npos)
        << out;
  }
  {  // Not the format at all.
    const auto [rc, out] = Promtool("vistream_x{scene=london} 1\n");
    EXPECT_NE(rc, 0) << out;
    EXPECT_NE(out.find("parsing error"), std::string::npos) << out;
  }
}

// An HTTP server on a free loopback port, for these tests.
std::unique_ptr<MetricsHttpServer> StartHttp(MetricsRegistry* r,
                                             std::function<bool()> healthy = nullptr) {
  absl::StatusOr<std::unique_ptr<MetricsHttpServer>> s =
      MetricsHttpServer::Start("127.0.0.1:0", r, std::move(healthy));
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

TEST(MetricsHttp, ServesTheRegistryOnMetrics) {
  MetricsRegistry r;
  Counter* c =
      r.GetCounter("vistream_pvs_computations_total", "PVSs computed.", {{"scene", "london"}});
  c->Add(4);
  std::unique_ptr<MetricsHttpServer> s = StartHttp(&r);
  ASSERT_NE(s, nullptr);
  EXPECT_GT(s->port(), 0);
  EXPECT_EQ(s->address(), "127.0.0.1:" + std::to_string(s->port()));

  httplib::Client client("127.0.0.1", s->port());
  httplib::Result res = client.Get("/metrics");
  ASSERT_TRUE(res) << httplib::to_string(res.error());
  EXPECT_EQ(res->status, 200);
  EXPECT_TRUE(res->get_header_value("Content-Type").starts_with("text/plain; version=0.0.4"))
      << res->get_header_value("Content-Type");
  EXPECT_EQ(res->body, r.Render());
  EXPECT_NE(res->body.find("vistream_pvs_computations_total{scene=\"london\"} 4\n"),
            std::string::npos)
      << res->body;

  c->Add();  // every request renders afresh
  res = client.Get("/metrics");
  ASSERT_TRUE(res) << httplib::to_string(res.error());
  EXPECT_NE(res->body.find("vistream_pvs_computations_total{scene=\"london\"} 5\n"),
            std::string::npos)
      << res->body;
}

TEST(MetricsHttp, HealthzIs200WhileHealthyAnd503WhileDraining) {
  MetricsRegistry r;
  std::atomic<bool> healthy{true};
  std::unique_ptr<MetricsHttpServer> s = StartHttp(&r, [&] { return healthy.load(); });
  ASSERT_NE(s, nullptr);
  httplib::Client client("127.0.0.1", s->port());
  for (bool h : {true, false, true}) {
    healthy = h;
    httplib::Result res = client.Get("/healthz");
    ASSERT_TRUE(res) << httplib::to_string(res.error());
    EXPECT_EQ(res->status, h ? 200 : 503);
    EXPECT_EQ(res->body, h ? "serving\n" : "draining\n");
  }
}

TEST(MetricsHttp, OtherPathsAre404) {
  MetricsRegistry r;
  std::unique_ptr<MetricsHttpServer> s = StartHttp(&r);
  ASSERT_NE(s, nullptr);
  httplib::Client client("127.0.0.1", s->port());
  for (const char* path : {"/", "/metric", "/metrics/x", "/healthz/", "/favicon.ico"}) {
    httplib::Result res = client.Get(path);
    ASSERT_TRUE(res) << path << ": " << httplib::to_string(res.error());
    EXPECT_EQ(res->status, 404) << path;
    EXPECT_NE(res->body.find("/metrics and /healthz"), std::string::npos)
        << path << ": " << res->body;
  }
}

TEST(MetricsHttp, MalformedAddressIsInvalidArgumentNamingIt) {
  MetricsRegistry r;
  for (const char* listen :
       {"", "9464", "127.0.0.1", "127.0.0.1:", ":9464", "127.0.0.1:http", "127.0.0.1:65536",
        "127.0.0.1:-1", "127.0.0.1:123456", "::1:9464", "[::1]9464", "[::1", "[]:9464"}) {
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> s =
        MetricsHttpServer::Start(listen, &r, nullptr);
    ASSERT_FALSE(s.ok()) << listen;
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument)
        << listen << ": " << s.status();
    EXPECT_NE(s.status().message().find(absl::StrCat("'", listen, "': expected HOST:PORT")),
              std::string::npos)
        << s.status();
  }
}

TEST(MetricsHttp, PortInUseIsUnavailableNamingAddressAndReason) {
  MetricsRegistry r;
  std::unique_ptr<MetricsHttpServer> first = StartHttp(&r);
  ASSERT_NE(first, nullptr);
  absl::StatusOr<std::unique_ptr<MetricsHttpServer>> second =
      MetricsHttpServer::Start(first->address(), &r, nullptr);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable) << second.status();
  EXPECT_EQ(second.status().message(),
            absl::StrCat("cannot listen for metrics on ", first->address(), ": the port ",
                         first->port(), " is in use"));
  // The first one still answers.
  httplib::Result res = httplib::Client("127.0.0.1", first->port()).Get("/healthz");
  ASSERT_TRUE(res) << httplib::to_string(res.error());
  EXPECT_EQ(res->status, 200);
}

TEST(MetricsHttp, StopIsIdempotentAndFreesThePort) {
  MetricsRegistry r;
  std::unique_ptr<MetricsHttpServer> s = StartHttp(&r);
  ASSERT_NE(s, nullptr);
  const std::string address = s->address();
  {
    // A kept-alive connection that has been served: Stop() still ends promptly.
    httplib::Client client("127.0.0.1", s->port());
    client.set_keep_alive(true);
    ASSERT_TRUE(client.Get("/healthz"));
    const auto start = std::chrono::steady_clock::now();
    s->Stop();
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(4));
  }
  s->Stop();
  httplib::Client client("127.0.0.1", s->port());
  client.set_connection_timeout(2);
  EXPECT_FALSE(client.Get("/healthz"));
  // The address is free again, for a server started in its place.
  absl::StatusOr<std::unique_ptr<MetricsHttpServer>> again =
      MetricsHttpServer::Start(address, &r, nullptr);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ((*again)->address(), address);
}

// ---- vistream-server's own metrics (server/service_metrics.h), through the executable ----

// The value of the series `series` (name and labels as rendered) in `text`; NaN when absent.
double SeriesValue(const std::string& text, const std::string& series) {
  for (const std::string& line : Lines(text, series + " ")) return std::stod(line.substr(series.size() + 1));
  return std::nan("");
}

// The server's /metrics port from its ready line ("...; metrics on http://HOST:PORT/metrics").
int MetricsPort(const std::string& ready) {
  const size_t at = ready.find("metrics on http://");
  if (at == std::string::npos) return -1;
  const size_t colon = ready.find(':', at + 18);
  return std::stoi(ready.substr(colon + 1));
}

std::string Fetch(int port, const std::string& path, int* status = nullptr) {
  httplib::Client client("127.0.0.1", port);
  auto r = client.Get(path);
  if (status != nullptr) *status = r ? r->status : -1;
  return r ? r->body : "";
}

TEST(ServerMetrics, AScriptedWalkMovesTheCountersAndPromtoolPassesOnTheOutput) {
  ASSERT_NO_FATAL_FAILURE(RequirePromtool());
  std::string error;
  auto server = test::RunningServer::Start(
      VISTREAM_SERVER_BIN, {"--scene", "city1", "--listen", "127.0.0.1:0", "--metrics-listen", "127.0.0.1:0"}, &error,
      testing::ProcessTempDir() + "/metrics_walk.log");
  ASSERT_NE(server, nullptr) << error;
  const int port = MetricsPort(server->ready_line());
  ASSERT_GT(port, 0) << server->ready_line();
  const std::string before = Fetch(port, "/metrics");
  for (const char* name : {"vistream_sessions_active", "vistream_sessions_ended_total", "vistream_bytes_sent_total",
                           "vistream_pvs_computations_total", "vistream_pvs_cache_hits_total",
                           "vistream_pvs_compute_seconds", "vistream_crossing_served_seconds",
                           "vistream_late_cells_total", "vistream_pvs_queue_length",
                           "vistream_process_resident_memory_bytes"}) {
    EXPECT_NE(before.find(std::string("# TYPE ") + name + " "), std::string::npos) << name << "\n" << before;
  }
  EXPECT_EQ(SeriesValue(before, "vistream_pvs_computations_total{scene=\"city1\"}"), 0.0);
  EXPECT_GT(SeriesValue(before, "vistream_process_resident_memory_bytes"), 1e6);

  // A walker in (4, 4) crosses into (5, 4): nine cells, then three more.
  client::SessionStream c(server->address());
  c.Start(client::SessionStream::HelloFor("city1"));
  c.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(c.SendPose(test::Centre(4, 4)));
  ASSERT_TRUE(c.WaitFor([](const client::SessionRecord& r) { return r.AllComplete(test::Around(test::Cell(4, 4))); },
                        test::kWait));
  ASSERT_TRUE(c.SendPose(test::Centre(5, 4), glm::dvec3(1.4, 0.0, 0.0)));
  ASSERT_TRUE(c.WaitFor([](const client::SessionRecord& r) { return r.AllComplete(test::Around(test::Cell(5, 4))); },
                        test::kWait));
  // Served is seen when the session is next asked for a message: give it a moment.
  std::string during;
  for (int k = 0; k < 100; ++k) {
    during = Fetch(port, "/metrics");
    if (SeriesValue(during, "vistream_crossing_served_seconds_count{scene=\"city1\"}") >= 1.0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(SeriesValue(during, "vistream_sessions_active{scene=\"city1\"}"), 1.0) << during;
  EXPECT_EQ(SeriesValue(during, "vistream_pvs_computations_total{scene=\"city1\"}"), 12.0) << during;
  EXPECT_EQ(SeriesValue(during, "vistream_pvs_compute_seconds_count{scene=\"city1\"}"), 12.0) << during;
  EXPECT_GT(SeriesValue(during, "vistream_bytes_sent_total{scene=\"city1\"}"), 1e4) << during;
  EXPECT_GT(SeriesValue(during, "vistream_geometry_bytes_sent_total{scene=\"city1\"}"), 1e4) << during;
  EXPECT_EQ(SeriesValue(during, "vistream_crossing_served_seconds_count{scene=\"city1\"}"), 1.0) << during;
  EXPECT_EQ(SeriesValue(during, "vistream_late_cells_total{scene=\"city1\"}"), 0.0) << during;
  EXPECT_TRUE(c.Finish().ok());
  std::string after;
  for (int k = 0; k < 100; ++k) {
    after = Fetch(port, "/metrics");
    if (SeriesValue(after, "vistream_sessions_ended_total{code=\"OK\",scene=\"city1\"}") >= 1.0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_EQ(SeriesValue(after, "vistream_sessions_ended_total{code=\"OK\",scene=\"city1\"}"), 1.0) << after;
  EXPECT_EQ(SeriesValue(after, "vistream_sessions_active{scene=\"city1\"}"), 0.0) << after;
  const auto [rc, out] = Promtool(after);
  EXPECT_EQ(rc, 0) << out << "\n" << after;
  EXPECT_EQ(out, "") << after;
  EXPECT_EQ(server->Stop(SIGTERM), 0);
}

// SIGTERM: /healthz says 503 while a session that stopped reading still holds the drain open.
TEST(ServerMetrics, HealthzTurns503OnSigtermBeforeTheSessionsEnd) {
  std::string error;
  auto server = test::RunningServer::Start(VISTREAM_SERVER_BIN,
                                           {"--scene", "city1", "--listen", "127.0.0.1:0", "--metrics-listen",
                                            "127.0.0.1:0", "--grace", "20"},
                                           &error, testing::ProcessTempDir() + "/metrics_drain.log");
  ASSERT_NE(server, nullptr) << error;
  const int port = MetricsPort(server->ready_line());
  int status = 0;
  EXPECT_EQ(Fetch(port, "/healthz", &status), "serving\n");
  EXPECT_EQ(status, 200);
  client::SessionStream stalled(server->address());
  stalled.Start(client::SessionStream::HelloFor("city1"), /*read=*/false);
  stalled.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(stalled.SendPose(test::Centre(4, 4)));
  std::this_thread::sleep_for(std::chrono::seconds(2));  // its writes fill the transport's window
  ASSERT_EQ(kill(server->pid(), SIGTERM), 0);
  bool draining = false;
  for (int k = 0; k < 200 && !draining; ++k) {
    const std::string body = Fetch(port, "/healthz", &status);
    draining = status == 503;
    if (!draining) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(draining) << "status " << status;
  // ... while the session is still open: the server counts it (the stalled client reads
  // nothing, so only the server can say).
  EXPECT_EQ(SeriesValue(Fetch(port, "/metrics"), "vistream_sessions_active{scene=\"city1\"}"), 1.0)
      << "the session ended before /healthz said 503";
  stalled.Cancel();
  EXPECT_EQ(server->Stop(0), 0);  // it ends by itself once the session is gone
}

}  // namespace
}  // namespace vistream::server
