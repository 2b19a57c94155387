//! The library's choices as command-line values: one clap `ValueEnum` per library enum, with
//! the same names, aliases and help, so clap stays in the binary.

/// A command-line value enum mirroring a library enum variant for variant.
macro_rules! choice {
    ($(#[$meta:meta])* $name:ident => $lib:path { $($(#[$vmeta:meta])* $variant:ident,)* }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
        pub enum $name { $($(#[$vmeta])* $variant,)* }
        impl From<$name> for $lib {
            fn from(choice: $name) -> Self {
                match choice { $($name::$variant => <$lib>::$variant,)* }
            }
        }
        impl $name {
            /// Parses the command-line name straight into the library's value.
            pub fn parser() -> impl clap::builder::TypedValueParser<Value = $lib> {
                clap::builder::TypedValueParser::map(
                    clap::builder::EnumValueParser::<$name>::new(),
                    <$lib>::from,
                )
            }
        }
    };
}

choice! {
    /// Sign convention of the angular errors of an analysis (`rotary analyze --sign`).
    Sign => errmap::rotary::analysis::Sign {
        /// err = α − β = commanded − measured (what `rotary table` compensates).
        Errmap,
        /// error = β − α = measured − commanded: ISO 230-2's deviation x (actual − target), the
        /// sign of laser and rotary-calibrator reports.
        Calibrator,
    }
}

choice! {
    /// Where networks are trained.
    Backend => errmap::nn::Backend {
        /// The fastest backend this machine has, by a short measurement cached per machine
        /// (`errmap gpu-info` shows the choice and why).
        Auto,
        /// Any wgpu adapter (a hardware GPU first, else software Vulkan such as lavapipe);
        /// fails instead of falling back.
        Gpu,
        /// The fast CPU trainer (SIMD, all cores).
        Cpu,
        /// The CPU reference trainer: the readable specification, slow.
        CpuReference,
    }
}

choice! {
    /// The plane of the circle: its first and second axis (angles run from +first toward +second).
    Plane => errmap::circular::input::Plane {
        Xy,
        Yz,
        Zx,
    }
}

choice! {
    /// The evaluation standard.
    Standard => errmap::linear::Standard {
        /// ISO 230-2:2014 (k = 2: R↑ = 4s, A from x̄ ± 2s).
        #[value(name = "iso230-2:2014")]
        Iso230_2_2014,
        /// ISO 230-2:1997 = GB/T 17421.2-2000 (same 2s/4s figures).
        #[value(name = "iso230-2:1997", alias = "gb/t17421.2-2000")]
        Iso230_2_1997,
        /// GB 10931-1989 (±3S: repeatability 6S).
        #[value(name = "gb10931-1989")]
        Gb10931_1989,
        /// VDI/DGQ 3441 (Ps = 6s̄, U, Pa, P).
        #[value(name = "vdi3441")]
        Vdi3441,
    }
}

choice! {
    AirFormula => errmap::linear::AirFormula {
        /// Ciddor (1996), NIST EMT Appendix A-III.
        Ciddor,
        /// Modified Edlén (Birch & Downs 1993/1994 + NIST water-vapour term), Appendix A-IV.
        Edlen,
    }
}

choice! {
    Method => errmap::interp::Method {
        /// Sibson's natural-neighbour interpolant: smooth except at the sites, never overshoots the data.
        NaturalNeighbour,
        /// Sibson's C1 interpolant with gradients from local quadratic fits: smooth at the sites too,
        /// follows curvature better, can overshoot near sharp features.
        SibsonC1,
        /// Barycentric interpolation on the Delaunay triangles: fastest, creased along triangle edges.
        Linear,
        /// Ordinary kriging (Gaussian process, Matérn 5/2 + nugget, maximum likelihood): smooths
        /// through probe noise; an O(n³) solve, at most 4000 points.
        Kriging,
    }
}

choice! {
    /// How the generator writes a part's probe file: errmap's CSV, or as an instrument would.
    ProbeFileFormat => errmap::synth::web_plate::ProbeFileFormat {
        /// `id,x_mm,y_mm,z_mm` (errmap's columns).
        Csv,
        /// A CMM's CSV export: a date line, then `POINT,X,Y,Z,I,J,K` (read with `columns`).
        CmmCsv,
        /// DMIS output: `F(P001)=FEAT/POINT,CART,…` nominals, then `FA(P001)=…` actuals.
        Dmis,
        /// ASCII point cloud `x y z`.
        Xyz,
        /// Binary little-endian PLY point cloud, double x, y, z.
        Ply,
    }
}

choice! {
    /// Control series whose parameter ranges are checked.
    FanucSeries => errmap::controller::FanucSeries {
        /// Series 0i-F (parameter manual B-64610EN).
        #[value(name = "0i-F")]
        Fs0iF,
        /// Series 30i/31i/32i-B (parameter manual B-64490EN).
        #[value(name = "30i-B")]
        Fs30iB,
    }
}

choice! {
    /// Controller file format (the same names for linear and rotary tables).
    TableFormat => errmap::controller::TableFormat {
        /// LinuxCNC `[JOINT_n]COMP_FILE`.
        Linuxcnc,
        /// Sinumerik 840D/828D/808D LEC (`$AA_ENC_COMP`) and direction-dependent CEC (`$AN_CEC`).
        Sinumerik,
        /// Fanuc pitch-error compensation parameters and data (0i-F, 30i-B).
        Fanuc,
        /// Heidenhain TNC `.COM` compensation-value table and its `.CMA` assignment table.
        Heidenhain,
        /// errmap's own CSV.
        Csv,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    /// Every command-line name is the library's own name of the same value.
    fn names_agree<C, L>(library_name: impl Fn(L) -> String)
    where
        C: ValueEnum + Into<L>,
    {
        for choice in C::value_variants() {
            let on_command_line = choice.to_possible_value().unwrap().get_name().to_string();
            assert_eq!(on_command_line, library_name(choice.clone().into()));
        }
    }

    fn serde_name<L: serde::Serialize>(value: L) -> String {
        serde_json::to_value(value)
            .unwrap()
            .as_str()
            .unwrap()
            .to_string()
    }

    #[test]
    fn command_line_names_are_the_library_names() {
        names_agree::<Sign, _>(serde_name::<errmap::rotary::analysis::Sign>);
        names_agree::<Backend, _>(|b: errmap::nn::Backend| b.name().to_string());
        names_agree::<Plane, _>(serde_name::<errmap::circular::input::Plane>);
        names_agree::<Standard, _>(|s: errmap::linear::Standard| s.name().to_string());
        names_agree::<AirFormula, _>(|f: errmap::linear::AirFormula| f.name().to_string());
        names_agree::<Method, _>(|m: errmap::interp::Method| m.name().to_string());
        names_agree::<ProbeFileFormat, _>(serde_name::<errmap::synth::web_plate::ProbeFileFormat>);
        names_agree::<FanucSeries, _>(|s: errmap::controller::FanucSeries| s.name().to_string());
        names_agree::<TableFormat, _>(|f: errmap::controller::TableFormat| f.name().to_string());
    }
}
