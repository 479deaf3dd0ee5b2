#pragma once
// N vistream-server replicas behind a real HAProxy on loopback, for fail-over tests
// (tools/replica_set.h: tools::Balancer), and what the tests ask of them.
//
// Needs a HAProxy executable (Debian haproxy 2.6): without one, Start fails saying so (a test
// never skips for it).

#include <chrono>
#include <string>
#include <vector>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

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

// The standard gRPC health service's answer for the whole server at `address`: "SERVING",
// "NOT_SERVING", or the call's error ("UNAVAILABLE: ...").
inline std::string GrpcHealth(const std::string& address) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub generic(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::Slice empty;
  auto call = generic.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::ByteBuffer(&empty, 1), &cq);
  call->StartCall();
  grpc::ByteBuffer reply;
  grpc::Status status;
  call->Finish(&reply, &status, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  if (!cq.Next(&tag, &ok)) return "no answer";
  if (!status.ok()) return std::to_string(status.error_code()) + ": " + status.error_message();
  std::vector<grpc::Slice> slices;
  std::string bytes;
  if (reply.Dump(&slices).ok()) {
    for (const grpc::Slice& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  // HealthCheckResponse: field 1 (status), varint: 1 SERVING, 2 NOT_SERVING.
  if (bytes == std::string("\x08\x01", 2)) return "SERVING";
  if (bytes == std::string("\x08\x02", 2)) return "NOT_SERVING";
  return "status bytes of length " + std::to_string(bytes.size());
}

}  // namespace vistream::server::test
