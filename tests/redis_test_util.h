#pragma once
// A real redis-server (Debian's) started by a test on a free loopback port, without
// persistence, and always stopped (tools/replica_set.h): the shared PVS store's tests run
// against it.

#include "tests/loopback_util.h"
#include "tools/replica_set.h"

namespace vistream::test {
using tools::RedisServer;
}  // namespace vistream::test
