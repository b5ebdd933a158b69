// The tele-presence stream (.artx, stream/container.h) on arbitrary bytes, through the receiver
// (StreamPlayer: header, the header's template, pose, coverage and atlas video decoding). Every
// input must play or give an artex::Error at construction; anything else (crash, other
// exception, sanitizer report, out-of-memory, hang) is a finding.
//
// The header and every record carry a CRC-32, which a mutation breaks almost always: each input
// is played twice, as it is (the CRC checks and the resynchronisation) and with its CRCs
// recomputed wherever the framing allows (the decoders behind them).
#include <zlib.h>

#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "stream/stream_player.h"

namespace {

uint32_t U32(const std::vector<uint8_t>& b, std::size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

void PutCrc(std::vector<uint8_t>* b, std::size_t from, std::size_t to) {
  const uint32_t crc =
      static_cast<uint32_t>(crc32(0L, b->data() + from, static_cast<uInt>(to - from)));
  std::memcpy(b->data() + to, &crc, 4);
}

// Recomputes the header's CRC and that of every record whose framing fits (docs/streaming.md:
// header size at byte 8; a record is "ARXF", frame u32, flags u8, reserved u8, pose u16,
// mask u32, video u32, from version 2 with flag bit 2 a rest shape's size u32, payloads, CRC-32).
void RepairCrcs(std::vector<uint8_t>* b) {
  if (b->size() < 12 || std::memcmp(b->data(), "ARTX", 4) != 0) return;
  const uint32_t header = U32(*b, 8);
  if (header < 24 || header > b->size()) return;
  PutCrc(b, 0, header - 4);
  uint16_t version = 0;
  std::memcpy(&version, b->data() + 4, 2);
  std::size_t at = header;
  while (at + 24 <= b->size()) {
    if (std::memcmp(b->data() + at, "ARXF", 4) != 0) {
      ++at;
      continue;
    }
    uint16_t pose = 0;
    std::memcpy(&pose, b->data() + at + 10, 2);
    const bool shape = version >= 2 && ((*b)[at + 8] & 4);
    const uint64_t size = 24ull + pose + U32(*b, at + 12) + U32(*b, at + 16) +
                          (shape ? 4ull + U32(*b, at + 20) : 0ull);
    if (at + size > b->size()) {
      ++at;
      continue;
    }
    PutCrc(b, at, at + size - 4);
    at += size;
  }
}

void Play(std::vector<uint8_t> bytes) {
  try {
    artex::StreamPlayer player(std::make_unique<artex::StreamReader>(std::move(bytes), "fuzz.artx"));
    artex::PlayedFrame frame;
    for (int i = 0; i < 64 && player.Next(&frame); ++i) {
    }
  } catch (const artex::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // The player writes the header's template to a temporary file: keep it in RAM too.
  ::setenv("TMPDIR", artex::fuzz::Scratch().c_str(), 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  Play(bytes);
  RepairCrcs(&bytes);
  Play(std::move(bytes));
  return 0;
}
