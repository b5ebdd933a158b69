// The status line of `artex experiment` (issue 17): finished sequence generations used to stay
// in the list of running jobs, so the line showed more running jobs than existed.
#include "experiments/progress_display.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

namespace artex {
namespace {

RunnerEvent Event(RunnerEvent::Kind kind, const std::string& label, int done = 0, int total = 0) {
  RunnerEvent e;
  e.kind = kind;
  e.label = label;
  e.done = done;
  e.total = total;
  e.runs_total = 4;
  return e;
}

class ProgressDisplayTest : public ::testing::Test {
 protected:
  void SetUp() override { out_ = std::tmpfile(); }
  void TearDown() override { std::fclose(out_); }
  std::string Written() {
    std::fflush(out_);
    std::rewind(out_);
    std::string s;
    char buf[1024];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof(buf), out_)) > 0) s.append(buf, n);
    return s;
  }
  FILE* out_ = nullptr;
};

TEST_F(ProgressDisplayTest, FinishedSequenceGenerationsLeaveTheRunningCount) {
  using K = RunnerEvent::Kind;
  ExperimentProgressDisplay display(out_, /*tty=*/true);
  display.Handle(Event(K::kPlan, ""));
  for (const char* seq : {"walk", "arms"}) {
    display.Handle(Event(K::kSequenceStarted, seq));
    display.Handle(Event(K::kSequenceProgress, seq, 3, 3));
  }
  EXPECT_EQ(display.generating(), 2);
  EXPECT_EQ(display.running(), 0);
  EXPECT_NE(display.StatusLine().find("0 running"), std::string::npos) << display.StatusLine();
  EXPECT_NE(display.StatusLine().find("generating walk 3/3"), std::string::npos);
  display.Handle(Event(K::kSequenceReady, "walk"));
  display.Handle(Event(K::kSequenceReady, "arms"));
  EXPECT_EQ(display.generating(), 0);

  display.Handle(Event(K::kRunStarted, "walk/base"));
  display.Handle(Event(K::kRunProgress, "walk/base", 1, 3));
  EXPECT_EQ(display.running(), 1);
  EXPECT_EQ(display.StatusLine(), "[0/4 done, 1 running]  walk/base 1/3");
  RunnerEvent finished = Event(K::kRunFinished, "walk/base");
  finished.runs_done = 1;
  display.Handle(finished);
  EXPECT_EQ(display.running(), 0);
  EXPECT_NE(Written().find("experiment: [1/4] done walk/base"), std::string::npos) << Written();
}

TEST_F(ProgressDisplayTest, WithoutTerminalWritesOneLinePerEvent) {
  using K = RunnerEvent::Kind;
  ExperimentProgressDisplay display(out_, /*tty=*/false);
  display.Handle(Event(K::kSequenceStarted, "walk"));
  display.Handle(Event(K::kSequenceProgress, "walk", 1, 3));
  display.Handle(Event(K::kSequenceReady, "walk"));
  display.Handle(Event(K::kRunStarted, "walk/base"));
  const std::string text = Written();
  EXPECT_EQ(text,
            "experiment: generating sequence walk\n"
            "experiment: sequence walk ready (reused)\n"
            "experiment: start walk/base\n");
}

}  // namespace
}  // namespace artex
