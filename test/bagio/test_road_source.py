"""road_from_source with bags: a bag folder is read as an LPA bag, every other source is core's."""
import numpy as np

from road_force_estimator import bagio
from road_force_estimator.bagio import road_source
from road_force_estimator.core.road import flat_profile, iso8608_profile


def test_bag_folders_go_to_read_profile_bag(tmp_path, monkeypatch):
    # read_profile_bag is tested in test_lpa.py and test_profile_export.py: check that a bag
    # folder is handed to it.
    bag = tmp_path / 'lpa_bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    seen = []
    profile = flat_profile(5.0)

    def read_profile_bag(path):
        seen.append(path)
        return profile

    monkeypatch.setattr(road_source, 'read_profile_bag', read_profile_bag)
    assert bagio.road_from_source(str(bag)) is profile
    assert seen == [bag]


def test_a_written_lpa_bag_and_the_other_sources(tmp_path):
    road = iso8608_profile('C', 20.0, seed=4)
    bagio.write_lpa_bag(tmp_path / 'lpa', road)
    back = bagio.road_from_source(str(tmp_path / 'lpa'))
    np.testing.assert_array_equal(back.distance_m, road.distance_m)
    np.testing.assert_array_equal(back.elevation_m, road.elevation_m)
    synthetic = bagio.road_from_source('iso8608:C:seed=4:length=20')
    np.testing.assert_array_equal(synthetic.elevation_m, road.elevation_m)
