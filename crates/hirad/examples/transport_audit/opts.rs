//! The command line: `SCENE [MODE] [options]` (see docs/transport-audit.md), and the solver
//! and path tracer settings it selects.
use hirad::radiosity::{Oracle, SolverConfig, VisibilityMode};
use hirad::render::ReferenceOptions;

/// The command line (defaults in `parse`).
pub struct Opts {
    /// Scene name or file (`Scene::load`).
    pub scene: String,
    /// What to audit (`irradiance` when not given).
    pub mode: String,
    /// `--two-sided`: two-sided surfaces.
    pub two_sided: bool,
    /// `--preset`: solver preset.
    pub preset: String,
    /// `--clustering`: cluster tree strategy.
    pub clustering: String,
    /// `--visibility`: overrides the preset's visibility mode.
    pub visibility: Option<String>,
    /// `--refine`: overrides the preset's refinement oracle.
    pub refine: Option<String>,
    /// `--samples`: samples per object (modes divide it per link, leaf or pixel).
    pub samples: usize,
    /// `--object`: the object to audit or to restrict to.
    pub object: Option<String>,
    /// `--source-mean` (`links`): Monte Carlo with the source element's mean radiosity.
    pub source_mean: bool,
    /// `--bins`: `irradiance` also bins each object's points over its planes (10 × 6).
    pub bins: bool,
    /// `--rays`: shadow rays per link.
    pub rays: Option<u32>,
    /// `--eps-rel`: overrides the preset's relative refinement threshold.
    pub eps_rel: Option<f64>,
    /// `--min-area-rel`: overrides the preset's smallest element area (relative).
    pub min_area_rel: Option<f64>,
    /// `--iters`: solver iterations at most (1: direct light only).
    pub iters: Option<u32>,
    /// `--depth`: the path tracer's bounce limit.
    pub depth: Option<u32>,
    /// `--rows`: rows to list.
    pub rows: usize,
    /// `--leaf` (`leaf`): the leaf element.
    pub leaf: Option<u32>,
    /// The solver's seed (`None`: the preset's).
    pub seed: Option<u64>,
    /// `--fov` (`image`): vertical field of view, degrees.
    pub fov: Option<f32>,
    /// `--shadow-levels`: overrides the preset's shadow levels.
    pub shadow_levels: Option<u32>,
}

/// Reads the command line; panics with a message on a malformed one.
pub fn parse() -> Opts {
    let mut a = std::env::args().skip(1);
    let mut o = Opts {
        scene: a
            .next()
            .expect("usage: transport_audit SCENE [MODE] [options]"),
        mode: "irradiance".into(),
        two_sided: false,
        preset: "default".into(),
        clustering: "proxi".into(),
        visibility: None,
        samples: 20_000,
        object: None,
        source_mean: false,
        bins: false,
        rays: None,
        eps_rel: None,
        min_area_rel: None,
        iters: None,
        depth: None,
        rows: 30,
        leaf: None,
        seed: None,
        fov: None,
        shadow_levels: None,
        refine: None,
    };
    while let Some(x) = a.next() {
        let mut val = || a.next().unwrap_or_else(|| panic!("{x} needs a value"));
        match x.as_str() {
            "--two-sided" => o.two_sided = true,
            "--preset" => o.preset = val(),
            "--clustering" => o.clustering = val(),
            "--visibility" => o.visibility = Some(val()),
            "--refine" => o.refine = Some(val()),
            "--samples" => o.samples = val().parse().expect("--samples N"),
            "--object" => o.object = Some(val()),
            "--source-mean" => o.source_mean = true,
            "--bins" => o.bins = true,
            "--rays" => o.rays = Some(val().parse().expect("--rays N")),
            "--eps-rel" => o.eps_rel = Some(val().parse().expect("--eps-rel X")),
            "--min-area-rel" => o.min_area_rel = Some(val().parse().expect("--min-area-rel X")),
            "--iters" => o.iters = Some(val().parse().expect("--iters N")),
            "--depth" => o.depth = Some(val().parse().expect("--depth N")),
            "--rows" => o.rows = val().parse().expect("--rows N"),
            "--leaf" => {
                let v = val();
                o.leaf = Some(if v == "max" {
                    u32::MAX
                } else {
                    v.parse().expect("--leaf ID|max")
                })
            }
            "--seed" => o.seed = Some(val().parse().expect("--seed N")),
            "--fov" => o.fov = Some(val().parse().expect("--fov DEGREES")),
            "--shadow-levels" => o.shadow_levels = Some(val().parse().expect("--shadow-levels N")),
            m if !m.starts_with("--") => o.mode = m.into(),
            _ => panic!("unknown option {x}"),
        }
    }
    o
}

impl Opts {
    /// The preset's solver settings with the command line's overrides.
    pub fn solver_config(&self) -> SolverConfig {
        let o = self;
        let mut cfg = SolverConfig::preset(&o.preset).expect("preset");
        cfg.two_sided = o.two_sided;
        if let Some(n) = o.rays {
            cfg.shadow_rays = n;
        }
        if let Some(e) = o.eps_rel {
            cfg.eps_rel = e;
        }
        if let Some(m) = o.min_area_rel {
            cfg.min_area_rel = m;
        }
        if let Some(n) = o.iters {
            cfg.max_iters = n;
        }
        if let Some(s) = o.seed {
            cfg.seed = s;
        }
        if let Some(n) = o.shadow_levels {
            cfg.shadow_levels = n;
        }
        if let Some(v) = &o.visibility {
            cfg.visibility = VisibilityMode::parse(v).expect("visibility");
        }
        if let Some(r) = &o.refine {
            cfg.refine = Oracle::parse(r).expect("refine");
        }
        cfg
    }

    /// The path tracer's settings: the sides, and `--depth` as its bounce limit when given.
    pub fn reference_options(&self) -> ReferenceOptions {
        let mut ropts = ReferenceOptions {
            two_sided: self.two_sided,
            ..Default::default()
        };
        if let Some(d) = self.depth {
            ropts.max_depth = d;
        }
        ropts
    }
}
