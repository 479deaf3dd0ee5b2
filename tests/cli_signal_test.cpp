// The vistream tool's ^C handling (tools/cli_common.h), in-process: raise() runs the handler
// before it returns, so the first and the second SIGINT are each seen for certain.
#include <csignal>
#include <cstdlib>

#include <gtest/gtest.h>

#include "tools/cli_common.h"

namespace vistream::tools {
namespace {

TEST(CancelHandler, AFirstInterruptOnlyRaisesTheFlag) {
  EXPECT_EXIT(
      {
        InstallCancelHandler();
        std::raise(SIGINT);
        std::_Exit(CancelFlag().load() ? 7 : 8);
      },
      ::testing::ExitedWithCode(7), "");
}

TEST(CancelHandler, ASecondInterruptStopsAtOnceSayingSo) {
  EXPECT_EXIT(
      {
        InstallCancelHandler();
        std::raise(SIGINT);
        std::raise(SIGINT);
        std::_Exit(8);
      },
      ::testing::ExitedWithCode(130), "vistream: interrupted \\(a second \\^C: stopped at once\\)");
}

}  // namespace
}  // namespace vistream::tools
