#pragma once
// Conversions between domain types and protocol messages, at the server's edge.

#include "proto/vec3.h"

namespace vistream::server {

using vistream::SetVec;
using vistream::ToVec;

}  // namespace vistream::server
