#pragma once
// N vistream-server replicas behind a real HAProxy on loopback, for fail-over tests
// (tools/replica_set.h: tools::Balancer), and what the tests ask of them.
//
// Needs a HAProxy executable (Debian haproxy 2.6): without one, Start fails saying so (a test
// never skips for it).

#include <chrono>
#include <string>
#include <vector>

#include "tests/grpc_health_util.h"
#include "tests/loopback_util.h"
#include "tests/server_process_util.h"
#include "tools/replica_set.h"

namespace vistream::server::test {

using ::vistream::test::FreeLoopbackPort;
using tools::Balancer;
using tools::BalancerOptions;
using tools::MetricsPortOf;

// The HTTP status of GET http://127.0.0.1:PORT/PATH; 0 when nothing answers.
inline int HttpStatus(int port, const std::string& path) { return ::vistream::test::HttpGet(port, path).first; }
// Its body.
inline std::string HttpBody(int port, const std::string& path) { return ::vistream::test::HttpGet(port, path).second; }

using ::vistream::test::GrpcHealth;

}  // namespace vistream::server::test
