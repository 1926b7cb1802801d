"""Settings of STAF's execution plan (controllers/staf_plan.py) and the constants it works with."""

from __future__ import annotations

from dataclasses import dataclass

WAY_CLEARANCE = 0.05
"""m between a body and the obstacles along every way home before a subteam starts home short of the taken slots
(`StafPlan._clear_ways`); chosen, not tuned: a little more than the 0.02 m at which the trainer counts a touch."""

SIGHT_STEP, SIGHT_REACH = 0.1, 1.0
"""m between the points checked along a robot's way to its target (a way that crosses a wall has one within half of
this of it), and how far along the path from the robot's own place a target out of sight may be put
(`StafPlan._in_sight`); chosen, not tuned: 1 m is about a robot's spacing in a formation (docs/staf_planned.md)."""


@dataclass
class PlanConfig:
    """Execution settings of STAF's plan (part of `method=staf_planned` and of `train_ppo.plan`)."""

    m: str = "2"
    """Subteams: a fixed number (2: STAF Table 1, Table 2 and Fig. 4 divide every team into two) or `auto` (our
    extension: the smallest m whose subteams fit the narrowest passage at the smallest spacing, STAF Sec. 7)."""
    adapt: str = "nominal"
    """Formation adaptation in a narrow passage: `nominal` (the plan keeps each subteam's formation at the team's
    nominal spacing and the policy deforms it itself, as STAF Sec. 3 attributes to the intermediate GNN under R^adp;
    what the shipped policy was trained on) or `geometric` (the plan shrinks the subteam's spacing to
    the free width ahead: our option for comparison, the STAF-planned journal (docs/staf_planned.md) "Learned
    adaptation")."""
    single_file: bool = True
    """Where a subteam's formation does not fit even at the smallest spacing (2r + min_gap; e.g. bollards 1.1 m
    apart, or five robots abreast in 2.4 m), the plan turns its slots into a column along the path (blended in over
    `file_ramp` metres); false keeps the formation's slots there too (docs/staf_planned.md)."""
    file_ramp: float = 2.0
    """Distance (m) over which slots blend from the formation into the column before a single-file stretch and back
    after it."""
    safe_gap: float = 0.3
    """Gap (m) between robot surfaces assumed when testing whether a subteam fits (as `high.safe_gap`)."""
    min_gap: float = 0.2
    """Smallest gap (m) between neighbouring robots' surfaces a shrunk formation may have."""
    margin: float = 0.15
    """Clearance (m) kept between a formation's outer robots and the walls."""
    speed: float = 0.8
    """Speed (m/s) of a subteam's anchor along the path (a fraction of max speed leaves room to catch up)."""
    max_lead: float = 0.8
    """The anchor waits when it is this far (m) ahead of its subteam's mean progress."""
    follow_gap: float = 0.6
    """Free space (m) between a subteam and the one ahead of it along the path."""
    split_distance: float = 5.0
    """The team splits when its progress is this close (m) to the first narrow part (at once if already closer)."""
    balance: bool = False
    """True: subteam sizes within one of each other (`highlevel.partition.balance_sizes`; the line's 3-1-3-3 becomes
    3-2-3-2); false: the cut's sizes as they are, as the shipped policy was trained (docs/staf_planned.md: no CFI
    gain)."""
    cut_frame: str = "travel"
    """The frame the deep graph cut sees the team in: `travel` (turned so that the team heads along +x,
    `plan_geometry.travel_frame`: the same subteams whichever way the map points) or `world` (the world's axes, as
    the shipped policy was trained; a ten-robot wedge heading north was cut 6-4 where heading east it is cut 7-3).
    docs/decisions.md."""
    high_checkpoint: str = ""
    """The deep graph cut (`stafpipe train-high`); empty: the shipped one."""
    home: str = "departure"
    """When the team's goal slots are given out: each time robots start for home (`departure`: the slots still free
    go to every robot not yet home-bound, from where its target is then, min-sum-of-squares as in Turpin, Michael and
    Kumar's CAPT, IJRR 2014), so robots arriving one by one do not cross each other's way; or once at the regroup
    (`regroup`, from the robots' positions then; what the shipped policy was trained with). docs/staf_planned.md."""
    target_gap: float = 0.1
    """> 0: targets of two robots closer than 2r + target_gap are pushed apart along the line joining them (a
    split or regroup slide can bring them closer than the robots' diameter); 0: off (the shipped policy was trained
    with 0). docs/staf_planned.md."""
    home_approach: float = 0.6
    """> 0: after the regroup, a subteam behind the first stops `follow_gap` short of the goal slots already taken,
    its robots then start for home, and a target more than this far behind its goal slot enters the slot from this
    far straight behind it (along the way in), so that robots arriving later do not cut past or into robots already
    seated; 0: as trained (later subteams follow the path to its end). docs/staf_planned.md."""
    extend_path: bool = True
    """The path reaches back straight behind its start (`PathFrame(extend=True)`): slots the plan places
    behind the start (a waiting subteam's, a column's rear) stay where they belong instead of all falling on the start
    point, where they crowded robots that stood behind or beside it; false: clipped to the path, as trained."""
    end_home: bool = True
    """After the regroup, a robot of a subteam whose anchor has reached the path's end starts for home once it is
    within a radius of its target (it can come no further); false: it waits until it has passed the last narrow
    stretch, as trained, and where that stretch reaches to the path's end it waits for ever. docs/staf_planned.md."""
    end_wait: float = 2.0
    """With `end_home`: such a robot also starts for home once it has moved less than 5 cm in this many seconds (its
    target, among robots already home, cannot be reached); 0: only within a radius of its target.
    docs/staf_planned.md."""
    in_sight: bool = True
    """A robot whose straight way to its target has crossed an obstacle for 2 s (a wall between them) aims instead at
    the path, up to 1 m from its own place on it, until its target is in sight again; false: it heads for its target
    through the wall and stays pressed against it, as trained. docs/staf_planned.md."""
    reorder: bool = True
    """Where a subteam is a column (single file), the column's order follows the robots' order along the path: two
    neighbours whose places are the other way round from where they stand (the one placed behind more than half a
    spacing ahead), the other not yet past the single-file stretch, swap places and formation slots; false: the order
    fixed at the split from the formation's slots, as trained. On a 1 m doorway the fixed order left a robot waiting
    on its column place in the door mouth while the one meant to go before it stood behind it against the wall, for
    ever (docs/staf_planned.md)."""
    reorder_lateral: bool = True
    """With `reorder`: while robots come in to a column, a robot's distance from the path counts as that much further
    behind, so that a robot out to the side of the column's line gives its place to one nearer the line instead of
    cutting across its way, from the moment the subteam starts to turn into a column (its slots follow once it is
    one); false: the order along the path alone, once it is a column, as trained
    (the STAF-planned journal (docs/staf_planned.md), "The column's order
    across the path")."""
    sight_wait: float = 1.0
    """Seconds a robot's way to its target must have crossed an obstacle before it aims at the path instead
    (`in_sight`): a robot sliding round a bollard sees its target again within a second, one pressed against a wall
    never does; 0 (at once) pulled robots sliding round bollards onto the path into their neighbours, and 2 s (an
    earlier policy's training) left an outer robot at a passage's mouth pressed against the wall's
    face until it turned into the corner. 1 s: chosen on 40 validation maps (docs/staf_planned.md)."""
    in_world: bool = True
    """Targets are kept inside the world's bounds, a radius and `margin` from its edge: a waiting subteam's column
    reaching back behind a start near the edge (`extend_path`) put targets outside the world, and robots drove into
    its edge; false: as trained (docs/staf_planned.md)."""
    separate_in_world: bool = True
    """With `in_world` and `target_gap`: targets are pushed apart inside the world's bounds (`separated(bounds=)`);
    false: pushed apart first and clipped to the bounds after, as the shipped policy was trained, which could bring
    two targets at the world's edge back to 0.12 m apart, and their robots into contact (docs/staf_planned.md)."""
    inside_out: bool = False
    """The order in which a row of a subteam files into its column (`plan_geometry.column_rank`): true, the robot
    nearest the path first, then outwards, left before right (a line abreast files in like a zip); false: from left
    to right, as trained (docs/staf_planned.md)."""
    short_of_ahead: float = 0.0
    """> 0: a target within 2r + this of a robot of its own subteam further along the path is put that far short of
    that robot, on the follower's side, so no robot aims into the one ahead of it (a column turning towards a door
    while its front robot still turns); 0: off, as trained (docs/staf_planned.md)."""
    lead_past_end: bool = True
    """A subteam's anchor leads its robots' mean progress by at most `max_lead` plus the length the path's end cuts
    off its column's slots (`StafPlan._cut_at_end`): a column longer than the way left to the goal no longer holds
    its anchor short of the end, where a robot still in the passage waited for ever (a 12-robot wedge through a door
    5 m before its goal; docs/staf_planned.md); false: `max_lead` alone, as trained."""
    hold_short: float = 0.15
    """> 0: while a robot waits for a target out of sight (`in_sight`, `sight_wait`), its target is held on its
    straight way where that way still keeps this gap (m) from the obstacle (`plan_geometry.short_of`): the network
    drives to its target and crept into the wall's face beside a passage's mouth, then caught the corner as it turned
    for the path (gen31_0002). 0.15: the teacher's stop gap (`imitation.stop_gap`), chosen against 0.05 on 40
    validation maps; 0: the target stays behind the wall, as trained (docs/staf_planned.md)."""
    sight_clear: bool = True
    """A robot that aims at the path instead of a target out of sight (`in_sight`) aims at the furthest point of the
    path, up to where it would aim without this, whose straight way keeps a radius and `hold_short` (at least
    `WAY_CLEARANCE`) from the obstacles (`plan_geometry.clear_arc`): not across a wall's corner; false: at the
    path's point 1 m ahead wherever it lies, as trained (docs/staf_planned.md)."""
    start_slots: bool = True
    """At the first step the robots take the team's slots, laid along the path, nearest to where they stand
    (Hungarian; robots are alike): a team whose formation faces another way than its path (`team.heading_deg` 180,
    or 0 on a map heading north) turns its formation on the way instead of every robot crossing the team to slot i;
    false: robot i keeps slot i, as trained (docs/staf_planned.md)."""
    track_progress: bool = True
    """Each robot's progress along the path is the projection on the part of the path within 2 m of arc length of its
    progress a step before (from the path's start at the first step): on a route that comes back near itself (Zhu et
    al.'s Scenario 1 loop, whose goal lies 0.5 m from its start) the nearest point of the whole path put robots at the
    start at its end; false: the nearest point of the whole path, as trained
    (the STAF-planned journal (docs/staf_planned.md), "Routes that come back
    near themselves")."""
    unblock: bool = True
    """At the split, the order of subteams with the fewest waiting robots met head-on (`plan_geometry.unblocked_order`;
    ties: the usual order, furthest ahead and nearest the path first); false: always the usual order, as trained."""

    def check(self, key: str) -> None:
        from stafpipe.errors import require

        require(
            self.m == "auto" or (self.m.isdigit() and 1 <= int(self.m) <= 4), f"{key}.m", "must be auto or 1-4", self.m
        )
        require(self.adapt in ("geometric", "nominal"), f"{key}.adapt", "must be geometric or nominal", self.adapt)
        lengths = ("safe_gap", "min_gap", "margin", "max_lead", "follow_gap", "split_distance", "file_ramp")
        for name in (*lengths, "sight_wait", "hold_short"):
            require(getattr(self, name) >= 0, f"{key}.{name}", "must be >= 0", getattr(self, name))
        require(self.speed > 0, f"{key}.speed", "must be > 0", self.speed)
        require(self.cut_frame in ("travel", "world"), f"{key}.cut_frame", "must be travel or world", self.cut_frame)
        require(self.home in ("regroup", "departure"), f"{key}.home", "must be regroup or departure", self.home)
        require(self.target_gap >= 0, f"{key}.target_gap", "must be >= 0", self.target_gap)
        require(self.short_of_ahead >= 0, f"{key}.short_of_ahead", "must be >= 0", self.short_of_ahead)
        require(self.home_approach >= 0, f"{key}.home_approach", "must be >= 0", self.home_approach)
        require(self.end_wait >= 0, f"{key}.end_wait", "must be >= 0", self.end_wait)
