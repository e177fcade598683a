//! The checks of a cloth's or mesh's behaviours beyond its springs, shared by both.

use super::validate::Issues;

/// A cloth's or mesh's behaviours, as its scene gives them, and its particle spacing (its
/// shortest spring at rest, m; none where its topology is not yet known to be sound).
pub(super) struct Behaviour {
    pub air: Option<crate::Aero>,
    pub tethers: Option<crate::TetherSpec>,
    pub limit: Option<crate::StretchLimit>,
    pub tearing: Option<crate::Tearing>,
    pub collide: Option<crate::SelfCollision>,
    pub spacing: Option<f64>,
}

impl Behaviour {
    /// A grid cloth's, its spacing the shorter of its cells' sides.
    pub(super) fn of_cloth(c: &super::Cloth) -> Self {
        let (cols, rows) = c.resolution;
        let spacing = (cols >= 2 && rows >= 2)
            .then(|| (c.size.0 / f64::from(cols - 1)).min(c.size.1 / f64::from(rows - 1)));
        Behaviour {
            air: c.air,
            tethers: c.tethers,
            limit: c.stretch_limit,
            tearing: c.tearing,
            collide: c.self_collision,
            spacing,
        }
    }
}

impl Issues {
    /// A cloth's or mesh's behaviours beyond its springs, located under `at` (`cloths[0]`).
    pub(super) fn behaviour(&mut self, at: &str, b: Behaviour) {
        let collide = b.collide.map(|c| {
            c.check()
                .and_then(|()| b.spacing.map_or(Ok(()), |s| c.check_spacing(s)))
        });
        let checks = [
            ("air", b.air.map(|a| a.check())),
            ("tethers", b.tethers.map(|t| t.check())),
            ("stretch_limit", b.limit.map(|l| l.check())),
            ("tearing", b.tearing.map(|t| t.check_beside(b.limit))),
            ("self_collision", collide),
        ];
        for (field, check) in checks {
            if let Some(Err(e)) = check {
                self.push(format!("{at}.{field}"), e);
            }
        }
    }
}
