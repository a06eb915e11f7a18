//! `bands=N` (sort-first bands of columns, each drawn by its own copy of a renderer on its own
//! thread) against `zbuffer`: frames bit-identical for every renderer that takes bands, over every
//! generator and over camera paths whose bands move from frame to frame (they are balanced on
//! the bands' times); bad counts and renderers that cannot draw bands refused.

use crate::support::{assert_identical_on_path, build_scene, identical_on_every_generator, spec};
use occult_render::{AlgoSpec, RenderError};

identical_on_every_generator! {
    zbuffer_in_three_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("zbuffer:bands=3", 1);
    frustum_in_four_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("frustum:bands=4", 1);
    hzb_in_three_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("hzb:bands=3", 1);
    /// The tests alone, every frame culled: a box is judged by its pixels in the band only.
    hzb_in_two_bands_without_payoff_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("hzb:bands=2,payoff=off", 2);
    clusters_in_two_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("clusters:bands=2,payoff=off", 1);
    oqgrid_in_three_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("oqgrid:bands=3,payoff=off", 1);
    nbuffer_in_two_bands_is_identical_on_every_generator:
        assert_variant_identical_on_every_generator("nbuffer:bands=2,payoff=off", 1);
}

#[test]
fn identical_on_paths_whose_bands_move() {
    for algo in [
        "hzb:bands=2",
        "hzb:bands=3,payoff=off",
        "clusters:bands=2",
        "oqgrid:bands=2,payoff=off",
    ] {
        assert_identical_on_path(&spec(algo), "city:blocks=3,detail=1", "street:12", 128, 96);
        assert_identical_on_path(&spec(algo), "forest:trees=2,patches=2", "flyover:8", 96, 64);
    }
}

#[test]
fn bad_band_counts_and_renderers_without_bands_are_refused() {
    for (bad, names) in [
        ("hzb:bands=0", "bands=0"),
        ("hzb:bands=65", "bands=65"),
        ("frustum:bands=two", "bands=two"),
        ("lzb:bands=2", "lzb"),
        ("rzb:bands=2", "rzb"),
    ] {
        let scene = std::sync::Arc::new(build_scene("city:blocks=1,detail=1").scene);
        match AlgoSpec::parse(bad).and_then(|s| s.build(scene, &Default::default())) {
            Err(RenderError::BadParameter(m)) => assert!(m.contains(names), "{bad}: {m}"),
            Err(e) => panic!("{bad}: another error: {e}"),
            Ok(_) => panic!("{bad} was accepted"),
        }
    }
}
