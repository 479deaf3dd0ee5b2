#pragma once
// What tests that start real servers on loopback share (tools/replica_set.h): a free port and a
// plain HTTP GET.

#include "tools/replica_set.h"

namespace vistream::test {
using tools::FreeLoopbackPort;
using tools::HttpGet;
}  // namespace vistream::test
