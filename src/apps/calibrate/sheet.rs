//! `calibrate.md`, the reading sheet: a Markdown template filled in one pass from the coupon's commanded
//! dimensions.

use super::*;

/// A length for the sheet: at most 4 decimals, trailing zeros trimmed.
fn mm(v: f64) -> String {
    emit::num(v, 4)
}

/// `calibrate.md` before its fields are filled in ([`fill`]): plain Markdown, one paragraph per source block.
const SHEET: &str = r#"# Calibration coupon: {machine}

`{program}` cuts six straight slots {depth} mm deep with tool `{tool}` (T{number}, {kind} D{d} mm) in {stock}:
three along Y that measure X, three along X that measure Y. Read with calipers (or a micrometer, or a scan),
they give the profile's keys `accuracy.backlash_um`, `accuracy.runout_um` and `accuracy.steps_per_mm`
({controller_keys}). Profile: {profile}. Estimated run time {time} ({time_blocks} at the planner's block rate).
The commanded dimensions are also in `{spec}`.

## 1. Stock, zero and cut

- A block of at least **{sx} x {sy} mm (X x Y), {sz} mm thick**, top faced flat, clamped or taped down (a
  larger block is fine: only machined walls are measured).
- **X0 Y0 on the block's front-left corner** (lowest X and Y), to within 1 mm: touch the tool on the left face
  and set `G10 L20 P1 X-{r}`, on the front face and set `G10 L20 P1 Y-{r}` (its radius). **Z0 on the top.**
- Every slot starts {clear} mm plus the tool's radius outside the left or front face and runs out past the far
  face, so the tool never plunges into material. Each of the {levels} depth level(s) is its own pass.
- Before each slot the measured axis makes a {take_up} mm take-up move (slots a and c moving +, slot b moving
  -) and it does not move while the slot is cut: do not jog during the program.

{cut_it}

## 2. The coupon (top view)

```
{sketch}
```

The X slots (`||`, along Y) are cut first, then the Y slots (`==`) across them. Of the four islands, each is
named by the lands it measures: its X width is land A_x (left) or B_x (right), its Y width A_y (front) or B_y
(back). P_x = {px} mm and P_y = {py} mm are the commanded distances from slot a's centre to slot c's.

| symbol | what to measure | with | commanded, mm |
| --- | --- | --- | --- |
| S | the width of each slot | inside jaws, gauge pins | {d} |
{rows}

Measure each land on both islands that have it and average, with light, even pressure at the top of the walls.

## 3. Read the errors

### Backlash: `accuracy.backlash_um`

While an axis keeps its direction the carriage lags b/2 behind the command; on a reversal it stands still for
b. Slots a and c were approached moving +, so they sit b/2 low; slot b moving -, so it sits b/2 high: land A
comes out A = W + b - (S - D), land B = W - b - (S - D) (W commanded), and the runout, the tool's true
diameter and the axis scale cancel in the difference:

- `accuracy.backlash_um[0] = 1000 * (A_x - B_x) / 2` and `accuracy.backlash_um[1] = 1000 * (A_y - B_y) / 2`;
  the third entry (Z) is not measured: leave it.

A difference within the calipers' resolution (or a small negative one) is no measurable backlash: write 0, or
measure the islands with a micrometer. Check: (A + B)/2 + S should be W + D.

### Runout: `accuracy.runout_um`

A tool running out by TIR sweeps a circle TIR wider than itself: every slot is S = D + TIR wide. Measure the
tool's diameter D across its flutes with a micrometer (nominal {d} mm; end mills are ground a little under it)
and S as the mean of the six slots (or (O - I)/2 of each axis):

- `accuracy.runout_um = 1000 * (S - D)`

The direct measurement is a dial indicator (1 or 2 um divisions) on the tool's shank below the collet or on
its cutting diameter, turning the spindle by hand: the total swing is the TIR. It changes each time the tool is
clamped; measure it with the collet you cut with.

### Steps per mm: `accuracy.steps_per_mm`

Slots a and c were approached alike, so backlash cancels between them, and the inner and outer spans differ
from the distance of their centres by -S and +S: their mean is what the axis really travelled for P.

- `L_x = (O_x + I_x) / 2`, `accuracy.steps_per_mm[0] = steps_old_x * P_x / L_x` (P_x = {px}, steps_old_x = {stx})
- `L_y = (O_y + I_y) / 2`, `accuracy.steps_per_mm[1] = steps_old_y * P_y / L_y` (P_y = {py}, steps_old_y = {sty})
- Z (the third entry; {z_key}) is not measured: 1 mm of depth is too short to read a scale on.

L within the calipers' error of P (about 0.02 mm, {pct} % over {px} mm) means the scale is right: keep it.

## 4. Set the keys

The profile declares now `backlash_um = {bl}`, `runout_um = {ro}`, `steps_per_mm = {st}`. Write the measured
values into its `[accuracy]` section (at most 500 um each):

```toml
[accuracy]
backlash_um = [BX, BY, {bz}]    # 1000 * (A - B) / 2 per axis
runout_um = R                  # 1000 * (S - D)
steps_per_mm = [SX, SY, SZ]    # steps_old * P / L; SZ unchanged
```

{controller}

`accuracy.steps_per_mm` must be what the controller uses: programs are written on its step grid. After changing
the scale cut a second coupon: L should now read P, the backlash as before. Not measured here: deflection
under load, Z backlash, squareness of X and Y.
"#;

/// How to cut it and what to set on the controller, per dialect (fields as in [`SHEET`]).
const GRBL: [&str; 3] = [
    "GRBL's `$100`-`$102`",
    "Cut it: `brdfmill stream {program} --port /dev/ttyUSB0 --check`. Clear the chips; leave the block clamped
until it is measured if you may want to cut it again.",
    "On the controller: `$100=SX` and `$101=SY` (read the old ones with `$$`). GRBL has no backlash
compensation: the profile's `backlash_um` makes brdfmill cut one-way and simulate the rest.",
];

/// See [`GRBL`].
const LINUXCNC: [&str; 3] = [
    "LinuxCNC's `SCALE`",
    "Cut it: load `{program}` in LinuxCNC. It changes to T{number} with `T{number} M6 G43 H{number}`; `{table}`
holds the profile's tools in LinuxCNC's format (`T{number} P{number} D{d} Z0`) if your table lacks them (Z is
touched off, so the length offsets are 0).",
    "On the controller: `SCALE` in the INI's `[JOINT_0]` and `[JOINT_1]` sections (steps or encoder counts per
mm): `SCALE_new = SCALE_old * P / L`. If you compensate backlash there (`BACKLASH`, mm, in the same
sections), cut the coupon again and write only what remains into the profile.",
];

/// `template` with each `{name}` replaced by its value in `fields` in one pass (a value is never read again,
/// so text from the profile cannot inject a field); an unknown name is left as it is.
fn fill(template: &str, fields: &[(&str, String)]) -> String {
    let mut out = String::with_capacity(template.len() * 2);
    let mut rest = template;
    while let Some(i) = rest.find('{') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        match after
            .find('}')
            .and_then(|j| fields.iter().find(|f| f.0 == &after[..j]).map(|f| (j, &f.1)))
        {
            Some((j, v)) => {
                out.push_str(v);
                rest = &after[j + 1..];
            }
            None => {
                out.push('{');
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// The top view of the coupon with its slots' positions.
fn sketch(s: &CouponSpec) -> String {
    let c = |f: &AxisFeatures, i: usize| format!("={}", mm(f.centres_mm[i]));
    let edge = "+----||----------||----------||----+";
    let island = |row: &str| format!("|    ||  A_x {row} ||  B_x {row} ||    |");
    let air = "|    ||          ||          ||    |";
    let mut lines = vec![format!("y={:<5}{edge}", mm(STOCK_MM[1])), format!("{:7}{air}", "")];
    for (k, name, dir, row) in [(2, "c", "+Y", "B_y"), (1, "b", "-Y", "A_y"), (0, "a", "+Y", "")] {
        let y = c(&s.y, k);
        lines.push(format!(
            "y{y:<6}====================================   Y slot {name} (moving {dir})"
        ));
        let body = if row.is_empty() { air.to_string() } else { island(row) };
        lines.push(format!("{:7}{body}", ""));
    }
    lines.push(format!("y=0    {edge}"));
    let end = format!("={}", mm(STOCK_MM[0]));
    let xs: [(usize, String); 5] = [
        (7, "=0".into()),
        (12, c(&s.x, 0)),
        (24, c(&s.x, 1)),
        (36, c(&s.x, 2)),
        (42, end),
    ];
    let mut line = String::new();
    for (col, text) in xs {
        line.push_str(&" ".repeat(col.saturating_sub(line.len()).max(usize::from(!line.is_empty()))));
        line.push('x');
        line.push_str(&text);
    }
    lines.push(line);
    lines.push(format!("{:12}X slot a    X slot b    X slot c", ""));
    lines.push(format!("{:12}(moving +X) (moving -X) (moving +X)", ""));
    lines.join("\n")
}

/// The table rows of the lands and spans of both axes.
fn rows(s: &CouponSpec) -> String {
    let mut o = String::new();
    for f in [&s.x, &s.y] {
        let (a, l) = (f.axis, f.axis.to_lowercase());
        let (before, after, line) = if a == "X" {
            ("left of", "right of", "row")
        } else {
            ("in front of", "behind", "column")
        };
        let [wa, wb, i, out] = [f.lands_mm[0], f.lands_mm[1], f.inner_span_mm, f.outer_span_mm].map(mm);
        let _ = writeln!(
            o,
            "| A_{l} | an island's {a} width {before} {a} slot b (land A) | outside jaws | {wa} |"
        );
        let _ = writeln!(
            o,
            "| B_{l} | an island's {a} width {after} {a} slot b (land B) | outside jaws | {wb} |"
        );
        let _ = writeln!(
            o,
            "| I_{l} | inner span in {a}: over both islands of a {line}, from the face on {a} slot a to the face \
             on {a} slot c | outside jaws | {i} |"
        );
        let _ = writeln!(
            o,
            "| O_{l} | outer span in {a}: from {a} slot a's outer wall to {a} slot c's outer wall | inside jaws \
             | {out} |"
        );
    }
    o.trim_end().to_string()
}

/// `calibrate.md`: the stock and zero, the features, how to read each and which key it sets.
pub fn sheet(s: &CouponSpec) -> String {
    let (t, a) = (&s.tool, &s.declared);
    let [keys, cut_it, controller] = match s.dialect {
        Dialect::Grbl => GRBL,
        Dialect::Linuxcnc => LINUXCNC,
    };
    let steps = |k: usize| {
        a.steps_per_mm
            .map_or("your controller's".into(), |v| emit::num(v[k], 3))
    };
    let list = |v: [f64; 3]| format!("[{}]", v.map(|x| emit::num(x, 3)).join(", "));
    let profile = if s.profile.is_empty() {
        "-".into()
    } else {
        s.profile.clone()
    };
    let common = [
        ("program", PROGRAM_FILE.to_string()),
        ("number", t.number.to_string()),
        ("d", mm(t.diameter_mm)),
        ("table", TOOL_TABLE_FILE.to_string()),
    ];
    let mut fields: Vec<(&str, String)> = vec![
        ("controller_keys", keys.to_string()),
        (
            "z_key",
            if s.dialect == Dialect::Grbl {
                "`$102`"
            } else {
                "`[JOINT_2] SCALE`"
            }
            .into(),
        ),
        ("cut_it", fill(cut_it, &common)),
        ("controller", fill(controller, &common)),
        ("machine", s.machine.clone()),
        ("profile", profile),
        ("spec", SPEC_FILE.to_string()),
        ("depth", mm(s.depth_mm)),
        ("tool", t.id.clone()),
        ("kind", t.kind.to_string()),
        ("r", mm(t.diameter_mm / 2.0)),
        ("stock", stock_name(s.stock).to_string()),
        ("time", hms(s.estimated_s)),
        ("time_blocks", hms(s.estimated_block_limited_s)),
        ("sx", mm(s.stock_mm[0])),
        ("sy", mm(s.stock_mm[1])),
        ("sz", mm(s.stock_mm[2])),
        ("clear", mm(ENTRY_CLEAR_MM)),
        ("levels", s.levels.to_string()),
        ("take_up", mm(TAKE_UP_MM)),
        ("sketch", sketch(s)),
        ("rows", rows(s)),
        ("px", mm(s.x.pitch_mm)),
        ("py", mm(s.y.pitch_mm)),
        ("stx", steps(0)),
        ("sty", steps(1)),
        ("pct", emit::num(100.0 * 0.02 / s.x.pitch_mm, 2)),
        ("bl", list(a.backlash_um)),
        ("ro", emit::num(a.runout_um, 3)),
        ("st", a.steps_per_mm.map_or("absent".into(), list)),
        ("bz", emit::num(a.backlash_um[2], 3)),
    ];
    fields.extend(common);
    fill(SHEET, &fields)
}
