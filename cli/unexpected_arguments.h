#ifndef VISTREAM_CLI_UNEXPECTED_ARGUMENTS_H_
#define VISTREAM_CLI_UNEXPECTED_ARGUMENTS_H_

// What the executables (vistream, vistream-server, vistream-client) say of arguments CLI11 did
// not take: named first, before any other complaint (a misspelt option often hides a required
// one), in the "<option>: <what is wrong>" form of every bad option.

#include <string>
#include <vector>

#include <absl/strings/str_join.h>

namespace vistream::cli {

// `remaining`: CLI11's App::remaining() (in any order); `command`: as the user typed it, e.g.
// "'vistream pvs'" or "vistream-server". Empty when nothing was left over. Options (leading
// '-') are named, without the values CLI11 left beside them; otherwise the stray values are.
inline std::string UnexpectedArguments(const std::vector<std::string>& remaining, const std::string& command) {
  std::vector<std::string> options, values;
  for (const std::string& r : remaining) (r.size() > 1 && r[0] == '-' ? options : values).push_back(r);
  if (!options.empty()) {
    return absl::StrJoin(options, ", ") + (options.size() > 1 ? ": not options of " : ": not an option of ") + command;
  }
  if (!values.empty()) {
    return "'" + absl::StrJoin(values, " ") + "': not expected by " + command + " (a value needs its option before it)";
  }
  return "";
}

}  // namespace vistream::cli

#endif  // VISTREAM_CLI_UNEXPECTED_ARGUMENTS_H_
