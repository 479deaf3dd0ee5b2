// The vistream tool's ^C handling (tools/cli_common.h), in-process: raise() runs the handler
// before it returns, so the first and the second SIGINT are each seen for certain.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <thread>

#include <gtest/gtest.h>

#include "cli/stop_signal.h"
#include "tools/cli_common.h"

namespace vistream::tools {
namespace {

// The rule vistream-server's SIGINT/SIGTERM handler shares: first, echoes within a second,
// then a second signal.
TEST(StopSignal, FirstThenEchoesWithinASecondThenASecondSignal) {
  std::atomic<bool> stop{false};
  std::atomic<int64_t> first_ns{0};
  EXPECT_EQ(cli::ClassifyStopSignal(&stop, &first_ns), cli::StopSignal::kFirst);
  EXPECT_TRUE(stop.load());
  EXPECT_GT(first_ns.load(), 0);
  EXPECT_EQ(cli::ClassifyStopSignal(&stop, &first_ns), cli::StopSignal::kEcho);
  EXPECT_EQ(cli::ClassifyStopSignal(&stop, &first_ns), cli::StopSignal::kEcho);
  first_ns -= 1000000000;  // as if the first came a second ago
  EXPECT_EQ(cli::ClassifyStopSignal(&stop, &first_ns), cli::StopSignal::kSecond);
}

TEST(CancelHandler, AFirstInterruptOnlyRaisesTheFlag) {
  EXPECT_EXIT(
      {
        InstallCancelHandler();
        std::raise(SIGINT);
        std::_Exit(CancelFlag().load() ? 7 : 8);
      },
      ::testing::ExitedWithCode(7), "");
}

TEST(CancelHandler, TheSameInterruptDeliveredTwiceCountsOnce) {
  EXPECT_EXIT(
      {
        InstallCancelHandler();
        std::raise(SIGINT);
        std::raise(SIGINT);  // as timeout(1) delivers it: to the child, then to its group
        std::_Exit(CancelFlag().load() ? 7 : 8);
      },
      ::testing::ExitedWithCode(7), "");
}

TEST(CancelHandler, ASecondInterruptASecondLaterStopsAtOnceSayingSo) {
  EXPECT_EXIT(
      {
        InstallCancelHandler();
        std::raise(SIGINT);
        std::this_thread::sleep_for(std::chrono::milliseconds(1100));
        std::raise(SIGINT);
        std::_Exit(8);
      },
      ::testing::ExitedWithCode(130), "vistream: interrupted \\(a second \\^C: stopped at once\\)");
}

}  // namespace
}  // namespace vistream::tools
