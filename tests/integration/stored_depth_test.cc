// common/stored_depth.h: which stored maps a view's geometric consistency check
// reads (the plan's views around it, and when an open stream must wait), the
// cache of their depths, and the view named when one of them is lost. The
// check itself is tested in tests/fusion/geometric_consistency_test.cc, the
// service's fused maps against lfrecon run's in service_plan_test and stream_test.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "common/job_store.h"
#include "common/stored_depth.h"
#include "common/test_util.h"
#include "pipeline/reconstruction_plan.h"
#include "util/error.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;

// 20 frames of 8x6 pixels, every other one selected and emitted after the
// frame after it (the plan's order: positions 0..9 = views 0, 2, ..., 18).
// With a frame gap of 1, 18 of the 20 frames are settled while the stream is
// open: the order is final for the views emitted before frame 18 (0..16).
JobGeometry Geometry(bool open) {
  JobGeometry g;
  g.id = "jstoreddepthtest";
  g.open = open;
  g.options.depth.max_frame_gap = 1;
  ReconstructionPlan& p = g.plan;
  for (int k = 0; k < 20; ++k) {
    PinholeView v;
    v.width = 8;
    v.height = 6;
    g.views.push_back(v);
    const bool selected = k % 2 == 0;
    p.selected.push_back(selected);
    p.emit_frame.push_back(selected ? k + 1 : -1);
    p.order_position.push_back(selected ? k / 2 : -1);
    if (selected) p.views.push_back(k), p.order.push_back(k);
  }
  return g;
}

void WriteDenseMap(const JobStore& js, const JobGeometry& g, int v, float depth) {
  DepthMap m(6, 8);
  m.depth.setTo(depth);
  fs::create_directories(js.MapPath(g.id, pb::MAP_DENSE, v).parent_path());
  js.WriteMap(g.id, DepthMapToProto(m, v, pb::MAP_DENSE));
}

TEST(StoredDepth, NeighboursAreThePlansViewsAtTheOffsets) {
  JobGeometry g = Geometry(false);
  bool complete = false;
  // View 8 is plan position 4: positions 3, 5, 2, 6, 0, 8 (4 - 8 and 4 + 8 are outside the plan).
  EXPECT_EQ(ConsistencyNeighbours(g, 8, &complete), (std::vector<int>{6, 10, 4, 12, 0, 16}));
  EXPECT_TRUE(complete);
  EXPECT_EQ(ConsistencyNeighbours(g, 18, &complete), (std::vector<int>{16, 14, 10, 2}));  // the last: before it only
  EXPECT_TRUE(complete);
  // An open stream: positions 0..8 are final. View 0 (position 0) has its last
  // neighbour there; view 2 (position 1) waits for position 9; view 18 is not final yet.
  g.open = true;
  EXPECT_EQ(ConsistencyNeighbours(g, 0, &complete), (std::vector<int>{2, 4, 8, 16}));
  EXPECT_TRUE(complete);
  EXPECT_EQ(ConsistencyNeighbours(g, 2, &complete), (std::vector<int>{0, 4, 6, 10}));
  EXPECT_FALSE(complete);
  EXPECT_TRUE(ConsistencyNeighbours(g, 18, &complete).empty());
  EXPECT_FALSE(complete);
  // A view not in the plan: nothing to compare with; an open stream's waits.
  EXPECT_TRUE(ConsistencyNeighbours(g, 3, &complete).empty());
  EXPECT_FALSE(complete);
  g.open = false;
  EXPECT_TRUE(ConsistencyNeighbours(g, 3, &complete).empty());
  EXPECT_TRUE(complete);
  // Off, or no densification: no neighbours, nothing to wait for.
  g.open = true;
  g.options.geometric_consistency.enabled = false;
  EXPECT_TRUE(ConsistencyNeighbours(g, 8, &complete).empty());
  EXPECT_TRUE(complete);
  g.options.geometric_consistency.enabled = true;
  g.options.densify = false;
  EXPECT_TRUE(ConsistencyNeighbours(g, 8, &complete).empty());
  EXPECT_TRUE(complete);
}

// On by default for a job, as for lfrecon run; JobOptions.no_geometric_consistency turns it off.
TEST(StoredDepth, JobOptionTurnsTheCheckOff) {
  pb::JobOptions o;
  EXPECT_TRUE(JobPipelineOptions(o).geometric_consistency.enabled);
  EXPECT_EQ(JobPipelineOptions(o).geometric_consistency.Delay(), 8);
  o.set_no_geometric_consistency(true);
  EXPECT_FALSE(JobPipelineOptions(o).geometric_consistency.enabled);
  EXPECT_EQ(JobPipelineOptions(o).geometric_consistency.Delay(), 0);
}

TEST(StoredDepth, CacheKeepsTheMostRecentlyUsedDepths) {
  lfrecon::testing::TempDir tmp;
  const JobStore js(tmp.path());
  const JobGeometry g = Geometry(false);
  for (int v : {0, 2, 4}) WriteDenseMap(js, g, v, 1.0f + v);
  StoredDepthCache cache(js, g.id, 2);
  EXPECT_EQ(cache.Depth(g, 0).at<float>(0, 0), 1.0f);
  EXPECT_EQ(cache.Depth(g, 2).at<float>(5, 7), 3.0f);
  EXPECT_EQ(cache.Depth(g, 0).at<float>(0, 0), 1.0f);  // 0 used last: 2 goes when 4 comes
  const cv::Mat four = cache.Depth(g, 4);
  for (int v : {0, 2, 4}) fs::remove(js.MapPath(g.id, pb::MAP_DENSE, v));
  EXPECT_EQ(cache.Depth(g, 0).at<float>(0, 0), 1.0f);  // kept: not read again
  EXPECT_EQ(cache.Depth(g, 4).at<float>(0, 0), 5.0f);
  try {
    cache.Depth(g, 2);
    ADD_FAILURE() << "view 2's map was evicted and removed";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(js.MapPath(g.id, pb::MAP_DENSE, 2).string()), std::string::npos) << e.what();
  }
  cache.Forget(4);
  EXPECT_THROW(cache.Depth(g, 4), InputError);
  EXPECT_EQ(four.at<float>(0, 0), 5.0f);  // a depth handed out stays valid after eviction
}

TEST(StoredDepthCheck, NamesTheNeighbourWhoseMapIsLost) {
  lfrecon::testing::TempDir tmp;
  const JobStore js(tmp.path());
  const JobGeometry g = Geometry(false);
  for (int v : {6, 10, 12, 0, 16}) WriteDenseMap(js, g, v, 1.0f);  // view 8's neighbours but 4
  StoredDepthCache cache(js, g.id, 18);
  DepthMap dense(6, 8);
  int unreadable = -1;
  EXPECT_THROW(CheckStoredDenseMap(g, 8, cv::Mat(), &cache, &dense, &unreadable), InputError);
  EXPECT_EQ(unreadable, 4);
  // Off: nothing is read, nothing changes.
  JobGeometry off = g;
  off.options.geometric_consistency.enabled = false;
  dense.depth.setTo(2.0f);
  const GeometricConsistencyStats s = CheckStoredDenseMap(off, 8, cv::Mat(), &cache, &dense, nullptr);
  EXPECT_EQ(s.foreground + s.dropped, 0);
  EXPECT_EQ(dense.CountValid(), 48);
}

}  // namespace
}  // namespace lfrecon::svc
