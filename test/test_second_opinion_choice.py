"""The second opinion's choice (:meth:`.second_opinion.SecondOpinion.choose`): which of the
correlation's leading labels it answers, and where it withholds the answer."""
from __future__ import annotations

import dataclasses

import numpy as np

from speed_sign_detector.recognition.classification import LABEL_END_OF_LIMIT
from speed_sign_detector.recognition.second_opinion import (
    CANDIDATE_PSR_GAP,
    CERTAIN_CLOSE_RUNNER_UP_DISMISSED_SCORE,
    COMPOSITE_ONLY_ANSWER_LEAD,
    COMPOSITE_ONLY_OVERRULE_LEAD,
    COMPOSITE_ONLY_RUNNER_UP_PSR,
    END_OF_LIMIT_LABEL,
    LIT_ON_DARK_OVERRULE_LEAD,
    RENDERED_ONLY_MAX_GAP,
    RENDERED_ONLY_MAX_RANK,
    RENDERED_ONLY_MIN_SCORE,
    UNSEEN_RUNNER_UP_CLOSE_PSR,
    UNSEEN_RUNNER_UP_DISMISS_LEAD,
    UNSEEN_RUNNER_UP_DISMISSED_SCORE,
    UNSEEN_RUNNER_UP_PSR,
    SecondOpinion,
)


def _opinion(labels: tuple[str, ...], real: tuple[str, ...]) -> SecondOpinion:
    size = len(labels)
    return SecondOpinion(labels, np.zeros(1, np.float32), np.ones(1, np.float32),
                         np.zeros((1, size), np.float32), np.zeros(size, np.float32), real)


def test_second_opinion_chooses_only_among_ranked_real_labels() -> None:
    opinion = _opinion(('30', '70', '80', '130', 'other_sign'), ('30', '70', '80', 'other_sign'))
    scores = np.asarray([0.9, 0.2, -0.5, -0.9, -1.0])  # the model reads 30, lead 0.7
    # it may overrule the correlation's winner with its runner-up ...
    assert opinion.choose(scores, ['70', '30', '80'], 2, 0.2) == '30'
    # ... but never picks a label the correlation did not rank among the leaders
    assert opinion.choose(scores, ['70', '80', '30'], 2, 0.2) is None
    # a small lead withholds the answer
    assert opinion.choose(np.asarray([0.9, 0.8, 0.0, 0.0, 0.0]), ['30', '70'], 2, 0.2) is None
    # a label learned from renderings only is never its choice over a real one
    rendered_best = np.asarray([0.1, -0.5, -0.5, 0.9, -1.0])
    assert opinion.choose(rendered_best, ['30', '130'], 2, 0.2) == '30'
    # the correlation's rendered-only winner stands where the model reads it too, or
    # ranks it among its best RENDERED_ONLY_MAX_RANK + 1 labels (a model that never saw
    # that value's real pixels names the nearest value it knows: it cannot vouch
    # against it); otherwise the answer is withheld, never turned into another limit
    assert opinion.choose(rendered_best, ['130', '30'], 2, 0.2) == '130'
    assert RENDERED_ONLY_MAX_RANK == 3 and RENDERED_ONLY_MAX_GAP < 2.0
    assert opinion.choose(scores, ['130', '30'], 2, 0.2) == '130'       # 4th, 1.8 below
    assert opinion.choose(scores, ['130', '80', '30'], 2, 0.2) == '130'
    far_below = np.asarray([1.0, 0.2, -0.5, -0.95, -1.0])               # 1.95 below
    assert opinion.choose(far_below, ['130', '30'], 2, 0.2) is None
    fifth = _opinion(('30', '70', '80', '100', '130', 'other_sign'),
                     ('30', '70', '80', '100', 'other_sign'))
    assert fifth.choose(np.asarray([0.9, 0.2, -0.3, -0.5, -0.6, -1.0]), ['130', '30'], 2,
                        0.2) is None                                   # 5th of the model's
    reads_no_sign = np.asarray([-0.9, -0.9, -0.9, -0.3, 0.9])           # best: other sign
    assert opinion.choose(reads_no_sign, ['130', '30'], 2, 0.2) is None
    # nor where its best label is "no sign" (clutter: a look-alike read as a 40)
    clutter = _opinion(('30', '40', 'no_sign', 'other_sign'), ('30', 'no_sign', 'other_sign'))
    assert clutter.choose(np.asarray([-1.0, -0.9, 0.6, -0.6]), ['40', '30'], 2, 0.2) is None
    assert clutter.choose(np.asarray([-1.0, -0.4, -0.9, 0.6]), ['40', '30'], 2, 0.2) is None
    assert clutter.choose(np.asarray([0.6, -0.4, -0.9, -0.6]), ['40', '30'], 2, 0.2) == '40'
    # a real winner may still be overruled by a real runner-up with a clear lead ...
    assert opinion.choose(scores, ['70', '30'], 2, 0.2, overrule_lead=0.5) == '30'
    # ... but a lead under overrule_lead withholds a limit the two disagree on
    assert opinion.choose(scores, ['70', '30'], 2, 0.2, overrule_lead=0.8) is None
    # agreeing with the winner needs no more than min_lead
    assert opinion.choose(scores, ['30', '70'], 2, 0.2, overrule_lead=0.8) == '30'
    unsure = np.asarray([0.1, 0.0, 0.0, -0.1, 0.2])   # the model reads no limit at all
    assert opinion.choose(unsure, ['130', '30'], 2, 0.2) is None
    # ... and not as "rather not 130": best, but below the floor of its score
    rather_not = np.asarray([-0.9, -0.9, -0.9, RENDERED_ONLY_MIN_SCORE - 0.1, -0.9])
    assert opinion.choose(rather_not, ['130', '30'], 2, 0.2) is None
    assert opinion.choose(rather_not + 0.2, ['130', '30'], 2, 0.2) == '130'
    assert opinion.choose(scores, [], 2, 0.2) is None


def test_a_crop_may_lower_the_floor_of_a_rendered_only_leader_the_model_reads_too() -> None:
    """``rendered_only_floor`` (a crop's ``crop_rendered_only_min_score``) lowers the least
    score at which the model's own best label, a leader it knows from renderings only,
    stands; it never raises the form's floor, and a leader the model does not read first
    is judged as before."""
    opinion = _opinion(('30', '70', '80', '130', 'other_sign'), ('30', '70', '80', 'other_sign'))
    weakly_130 = np.asarray([-0.9, -0.9, -0.9, RENDERED_ONLY_MIN_SCORE - 0.2, -0.9])
    assert opinion.choose(weakly_130, ['130', '30'], 2, 0.2) is None
    assert opinion.choose(weakly_130, ['130', '30'], 2, 0.2,
                          rendered_only_floor=RENDERED_ONLY_MIN_SCORE - 0.3) == '130'
    assert opinion.choose(weakly_130, ['130', '30'], 2, 0.2,
                          rendered_only_floor=RENDERED_ONLY_MIN_SCORE - 0.1) is None
    clearly_130 = weakly_130 + 0.3                     # above the form's floor
    assert opinion.choose(clearly_130, ['130', '30'], 2, 0.2, rendered_only_floor=0.9) == '130'
    far_below = np.asarray([1.0, 0.2, -0.5, -0.95, -1.0])   # the model reads 30: unchanged
    assert opinion.choose(far_below, ['130', '30'], 2, 0.2, rendered_only_floor=-1.0) is None


def test_second_opinion_withholds_a_limit_close_to_one_it_cannot_vouch_against() -> None:
    """A limit the model knows from renderings only, ranked by the correlation within
    UNSEEN_RUNNER_UP_PSR of its leading limit, withholds the answer."""
    opinion = _opinion(('30', '60', '80', 'other_sign'), ('30', '80', 'other_sign'))
    reads_80 = np.asarray([-0.9, -0.9, 0.9, -1.0])
    close = [('80', 12.0), ('60', 12.0 - UNSEEN_RUNNER_UP_PSR + 0.1), ('30', 9.0)]
    far = [('80', 12.0), ('60', 12.0 - UNSEEN_RUNNER_UP_PSR - 0.1), ('30', 9.0)]
    assert opinion.choose(reads_80, ['80', '60', '30'], 3, 0.2, 1.0, close) is None
    assert opinion.choose(reads_80, ['80', '60', '30'], 3, 0.2, 1.0, far) == '80'
    # a real runner-up that close is the model's to judge
    real_close = [('80', 12.0), ('30', 11.9)]
    assert opinion.choose(reads_80, ['80', '30'], 3, 0.2, 1.0, real_close) == '80'
    # without the correlation's PSRs there is no such check
    assert opinion.choose(reads_80, ['80', '60', '30'], 3, 0.2, 1.0) == '80'


def _network_opinion(labels: tuple[str, ...], real: tuple[str, ...]) -> SecondOpinion:
    """A network-form opinion (one member, one hidden unit): :meth:`choose` takes the
    scores as given, the form decides which rules apply."""
    size = len(labels)
    return SecondOpinion(labels, np.zeros(1, np.float32), np.ones(1, np.float32),
                         np.zeros((1, 1, size), np.float32), np.zeros((1, size), np.float32),
                         real, hidden_weights=np.zeros((1, 1, 1), np.float32),
                         hidden_bias=np.zeros((1, 1), np.float32))


def test_a_network_that_dismisses_the_close_unseen_limit_answers_the_leader() -> None:
    """The network form answers the correlation's leader despite a limit it knows from
    renderings only within UNSEEN_RUNNER_UP_PSR, where it agrees with the leader with a
    lead of UNSEEN_RUNNER_UP_DISMISS_LEAD, scores that limit at most
    UNSEEN_RUNNER_UP_DISMISSED_SCORE, and the limit lies at least UNSEEN_RUNNER_UP_CLOSE_PSR
    below the leader; any one of these missing, the answer is withheld as before."""
    labels, real = ('30', '40', '80', 'other_sign'), ('30', '80', 'other_sign')
    network = _network_opinion(labels, real)
    assert network.form == 'network'
    dismissed = UNSEEN_RUNNER_UP_DISMISSED_SCORE - 0.0005
    reads_80 = np.asarray([1.0 - UNSEEN_RUNNER_UP_DISMISS_LEAD - 0.05, dismissed, 1.0, -1.0])
    gap = (UNSEEN_RUNNER_UP_CLOSE_PSR + UNSEEN_RUNNER_UP_PSR) / 2
    assert UNSEEN_RUNNER_UP_CLOSE_PSR < gap < UNSEEN_RUNNER_UP_PSR
    between = [('80', 12.0), ('40', 12.0 - gap), ('30', 9.0)]
    ranked = ['80', '40', '30']
    assert network.choose(reads_80, ranked, 3, 0.2, 1.0, between) == '80'
    # the same scores in the linear form: no dismissal, withheld
    assert _opinion(labels, real).choose(reads_80, ranked, 3, 0.2, 1.0, between) is None
    # the unseen limit scored above the dismissed score: withheld
    sees_40 = reads_80.copy()
    sees_40[1] = UNSEEN_RUNNER_UP_DISMISSED_SCORE + 0.0005
    assert network.choose(sees_40, ranked, 3, 0.2, 1.0, between) is None
    # a lead under UNSEEN_RUNNER_UP_DISMISS_LEAD: withheld
    unsure = reads_80.copy()
    unsure[0] = 1.0 - UNSEEN_RUNNER_UP_DISMISS_LEAD + 0.05
    assert network.choose(unsure, ranked, 3, 0.2, 1.0, between) is None
    # the unseen limit within UNSEEN_RUNNER_UP_CLOSE_PSR of the leader: withheld
    close = [('80', 12.0), ('40', 12.0 - UNSEEN_RUNNER_UP_CLOSE_PSR / 2), ('30', 9.0)]
    assert network.choose(reads_80, ranked, 3, 0.2, 1.0, close) is None
    # the model's best label not the leader (it would overrule the 30 leading): withheld
    overrules = [('30', 12.0), ('40', 12.0 - gap), ('80', 11.5)]
    assert network.choose(reads_80, ['30', '40', '80'], 3, 0.2, 0.5, overrules) is None
    far_40 = [('30', 12.0), ('80', 11.5), ('40', 12.0 - UNSEEN_RUNNER_UP_PSR - 0.1)]
    assert network.choose(reads_80, ['30', '80', '40'], 3, 0.2, 0.5, far_40) == '80'


def test_second_opinion_answers_no_label_the_correlation_barely_sees() -> None:
    """A label other than the correlation's leader is the model's answer only where the
    correlation found it within CANDIDATE_PSR_GAP of its leading PSR."""
    opinion = _opinion(('30', '50', '80', 'other_sign'), ('30', '50', '80', 'other_sign'))
    reads_50 = np.asarray([-1.0, 0.9, -0.9, -1.0])
    ranked = ['80', '30', 'other_sign', '50']
    near = [('80', 10.0), ('30', 9.5), ('other_sign', 9.0), ('50', 10.0 - CANDIDATE_PSR_GAP + 0.1)]
    far = near[:3] + [('50', 10.0 - CANDIDATE_PSR_GAP - 0.1)]
    assert opinion.choose(reads_50, ranked, 4, 0.2, 1.0, near) == '50'
    assert opinion.choose(reads_50, ranked, 4, 0.2, 1.0, far) is None
    # a label ranked without a PSR of its own (the real filters' ranking) is not answered
    assert opinion.choose(reads_50, ranked, 4, 0.2, 1.0, near[:3]) is None
    # the correlation's own leader needs no such check, however far the rest lie
    reads_80 = np.asarray([-1.0, -0.9, 0.9, -1.0])
    assert opinion.choose(reads_80, ranked, 4, 0.2, 1.0, far) == '80'
    # without the correlation's PSRs there is no check
    assert opinion.choose(reads_50, ranked, 4, 0.2, 1.0) == '50'


def test_overruling_a_value_known_from_composites_only_needs_a_clear_lead() -> None:
    """The model turns the correlation's leading limit into another only with a lead of
    COMPOSITE_ONLY_OVERRULE_LEAD where either is known from composites only."""
    labels = ('20', '100', '120', 'other_sign')
    opinion = dataclasses.replace(_opinion(labels, labels),
                                  crop_labels=('20', '100', 'other_sign'))
    reads_100 = np.asarray([-1.0, 0.7, -0.8, -1.0])              # lead 1.5 over 120
    assert COMPOSITE_ONLY_OVERRULE_LEAD > 1.5
    assert opinion.choose(reads_100, ['120', '100'], 2, 0.2, 1.0) is None
    assert opinion.choose(np.asarray([-1.0, 1.0, -1.0, -1.0]), ['120', '100'], 2, 0.2,
                          1.0) == '100'                          # lead 2.0
    # between two values with real crops the usual overrule lead holds
    assert opinion.choose(np.asarray([-0.8, 0.7, -1.0, -1.0]), ['20', '100'], 2, 0.2,
                          1.0) == '100'
    # agreeing with the correlation on it needs COMPOSITE_ONLY_ANSWER_LEAD (next test)
    assert opinion.choose(np.asarray([-1.0, -0.9, 0.9, -1.0]), ['120', '100'], 2, 0.2,
                          1.0) == '120'
    # a model all but certain (lead 1.96: both scores near the ends of their range)
    # overrules; just under COMPOSITE_ONLY_OVERRULE_LEAD it does not
    assert 1.9 < COMPOSITE_ONLY_OVERRULE_LEAD < 1.96
    assert opinion.choose(np.asarray([-1.0, 0.98, -0.98, -1.0]), ['120', '100'], 2, 0.2,
                          1.0) == '100'
    assert opinion.choose(np.asarray([-1.0, 0.93, -0.98, -1.0]), ['120', '100'], 2, 0.2,
                          1.0) is None
    # banks that do not record their crop labels treat every real label as one
    assert _opinion(labels, labels).choose(reads_100, ['120', '100'], 2, 0.2, 1.0) == '100'


def test_a_three_digit_answer_close_to_a_three_digit_composite_value_is_withheld() -> None:
    """A 100 or 120 (real crops) is withheld where the correlation finds a three-digit
    value known from composites only (130) within COMPOSITE_ONLY_RUNNER_UP_PSR of it: a
    small 130 whose middle digit the model reads as a 0."""
    labels = ('30', '100', '130', 'other_sign')
    opinion = dataclasses.replace(_opinion(labels, labels),
                                  crop_labels=('30', '100', 'other_sign'))
    reads_100 = np.asarray([-1.0, 0.9, -0.9, -1.0])
    close = COMPOSITE_ONLY_RUNNER_UP_PSR - 0.1
    far = COMPOSITE_ONLY_RUNNER_UP_PSR + 0.1
    ranked = ['100', '130', '30']
    assert opinion.choose(reads_100, ranked, 3, 0.2, 1.0,
                          [('100', 10.0), ('130', 10.0 - close), ('30', 7.0)]) is None
    assert opinion.choose(reads_100, ranked, 3, 0.2, 1.0,
                          [('100', 10.0), ('130', 10.0 - far), ('30', 7.0)]) == '100'
    # two-digit answers are not concerned (their partners are LONGER_PARTNERS' business)
    reads_30 = np.asarray([0.9, -0.9, -0.9, -1.0])
    assert opinion.choose(reads_30, ['30', '130'], 3, 0.2, 1.0,
                          [('30', 10.0), ('130', 10.0 - close)]) == '30'


def test_answering_a_value_known_from_composites_only_needs_a_clear_lead() -> None:
    """A limit the model knows from composites only (no real crop of it) is answered only
    with a lead of COMPOSITE_ONLY_ANSWER_LEAD, even where the correlation ranks it first:
    a real 100 read as the composite 10 by both is withheld."""
    labels = ('10', '30', '100', 'other_sign')
    opinion = dataclasses.replace(_opinion(labels, labels),
                                  crop_labels=('30', '100', 'other_sign'))
    assert 1.5 < COMPOSITE_ONLY_ANSWER_LEAD < 2.0
    reads_10 = np.asarray([0.75, -0.91, -0.95, -1.0])             # lead 1.66
    assert opinion.choose(reads_10, ['10', '30'], 3, 0.2, 1.0) is None
    sure_10 = np.asarray([0.9, -0.95, -0.95, -1.0])               # lead 1.85
    assert opinion.choose(sure_10, ['10', '30'], 3, 0.2, 1.0) == '10'
    # a value with real crops needs no more than min_lead
    reads_30 = np.asarray([-0.9, 0.2, -0.3, -1.0])                # lead 0.5
    assert opinion.choose(reads_30, ['30', '10'], 3, 0.2, 1.0) == '30'
    # banks that do not record their crop labels treat every real label as one
    assert _opinion(labels, labels).choose(reads_10, ['10', '30'], 3, 0.2, 1.0) == '10'


def test_second_opinion_never_turns_a_limit_into_an_end_of_limit() -> None:
    assert END_OF_LIMIT_LABEL == LABEL_END_OF_LIMIT
    opinion = _opinion(('20', '30', END_OF_LIMIT_LABEL, 'other_sign'),
                       ('20', '30', END_OF_LIMIT_LABEL, 'other_sign'))
    reads_end = np.asarray([-0.6, -0.9, 0.8, -0.9])
    # the correlation read 20 first: the model's end of limit withholds the answer
    assert opinion.choose(reads_end, ['20', END_OF_LIMIT_LABEL], 2, 0.2) is None
    # it confirms an end of limit the correlation read, or one over an unknown sign
    assert opinion.choose(reads_end, [END_OF_LIMIT_LABEL, '20'], 2, 0.2) == END_OF_LIMIT_LABEL
    assert opinion.choose(reads_end, ['other_sign', END_OF_LIMIT_LABEL], 2,
                          0.2) == END_OF_LIMIT_LABEL


def test_a_sign_read_inverted_keeps_an_unseen_leader_only_as_the_models_best() -> None:
    """No real crop shows an electronic sign: the model learned every value of that
    design from renderings alike, so on a sign read inverted (``lit_on_dark``) the
    correlation's leader known from renderings only (40) stands only where the model reads
    it too, not where the model ranks it a distant fourth behind the 60 the correlation
    found nearly as well; the model's own choice then stands on the usual rules."""
    opinion = _opinion(('40', '60', '80', 'no_sign', 'other_sign'),
                       ('60', '80', 'no_sign', 'other_sign'))
    reads_sixty = np.asarray([-0.9, 0.8, -0.95, -0.95, -1.0])  # 40 at 1.7 below, 2nd
    ranked = ['40', '60', '80']
    correlation = [('40', 12.1), ('60', 11.5), ('80', 10.5)]
    assert opinion.choose(reads_sixty, ranked, 4, 0.6, 1.2, correlation) == '40'
    assert LIT_ON_DARK_OVERRULE_LEAD > 1.75
    assert opinion.choose(reads_sixty, ranked, 4, 0.6, 1.2, correlation,
                          lit_on_dark=True) is None  # withheld, not turned into 60
    # there the model's own choice is judged as any other: an overrule of a leader known
    # from renderings only needs LIT_ON_DARK_OVERRULE_LEAD (the painted sign's
    # COMPOSITE_ONLY_OVERRULE_LEAD is more: no real crop vouches for either design)
    assert LIT_ON_DARK_OVERRULE_LEAD < 1.85 < COMPOSITE_ONLY_OVERRULE_LEAD
    surer_sixty = np.asarray([-0.9, 0.9, -0.95, -0.95, -1.0])  # lead 1.85
    assert opinion.choose(surer_sixty, ranked, 4, 0.6, 1.2, correlation,
                          lit_on_dark=True) == '60'
    sure_sixty = np.asarray([-0.99, 0.99, -0.99, -0.99, -1.0])
    assert opinion.choose(sure_sixty, ranked, 4, 0.6, 1.2, correlation,
                          lit_on_dark=True) == '60'
    reads_forty = np.asarray([0.8, -0.8, -0.95, -0.95, -1.0])
    assert opinion.choose(reads_forty, ranked, 4, 0.6, 1.2, correlation,
                          lit_on_dark=True) == '40'
    # the model's own reading of a real label is untouched by the polarity
    real_leader = [('60', 12.1), ('80', 9.0)]
    assert opinion.choose(reads_sixty, ['60', '80'], 4, 0.6, 1.2, real_leader,
                          lit_on_dark=True) == '60'


def test_a_sign_read_inverted_that_the_model_reads_as_the_leader_needs_no_real_crops() -> None:
    """On a sign read inverted whose best label by the model is the correlation's leader,
    a value known from composites only (110) needs no COMPOSITE_ONLY_ANSWER_LEAD, and a
    value known from renderings only close behind it (140) does not withhold it: the
    model learned that design of every value from renderings alike. On a painted sign
    both guards stand."""
    labels = ('40', '100', '110', '140', 'other_sign')
    opinion = dataclasses.replace(
        _opinion(labels, ('100', '110', 'other_sign')), crop_labels=('100', 'other_sign'))
    reads_110 = np.asarray([-1.0, -0.8, 0.79, -0.8, -1.0])      # lead 1.59 over 100
    assert reads_110[2] - reads_110[1] < COMPOSITE_ONLY_ANSWER_LEAD
    ranked = ['110', '140', '100']
    far = [('110', 14.0), ('140', 10.8), ('100', 9.4)]
    assert opinion.choose(reads_110, ranked, 4, 0.6, 1.2, far) is None
    assert opinion.choose(reads_110, ranked, 4, 0.6, 1.2, far, lit_on_dark=True) == '110'
    close = [('110', 14.0), ('140', 14.0 - UNSEEN_RUNNER_UP_PSR + 0.2), ('100', 9.4)]
    assert opinion.choose(reads_110, ranked, 4, 0.6, 1.2, close, lit_on_dark=True) == '110'
    # where the model's best is not the leader, the runner-up guard stands inverted too
    reads_100 = np.asarray([-1.0, 0.99, -0.99, -0.99, -1.0])
    assert opinion.choose(reads_100, ['110', '140', '100'], 4, 0.6, 1.2, close,
                          lit_on_dark=True) is None


def test_on_a_lit_face_a_rendered_only_leader_stands_only_as_the_models_best() -> None:
    """A sign read painted whose face glows in dark surroundings (``lit_face``: a
    dark-on-lit electronic sign) gets the rendered-only leader's rule of a sign read
    inverted, and only that: the 40 the model ranks second within the gap is withheld,
    the 40 it reads stands, and the model's 60 is then judged as on a painted sign."""
    opinion = _opinion(('40', '60', '80', 'no_sign', 'other_sign'),
                       ('60', '80', 'no_sign', 'other_sign'))
    reads_sixty = np.asarray([-0.9, 0.8, -0.95, -0.95, -1.0])
    ranked = ['40', '60', '80']
    correlation = [('40', 12.1), ('60', 11.5), ('80', 10.5)]
    assert opinion.choose(reads_sixty, ranked, 4, 0.6, 1.2, correlation) == '40'
    assert opinion.choose(reads_sixty, ranked, 4, 0.6, 1.2, correlation,
                          lit_face=True) is None
    reads_forty = np.asarray([0.8, -0.8, -0.95, -0.95, -1.0])
    assert opinion.choose(reads_forty, ranked, 4, 0.6, 1.2, correlation,
                          lit_face=True) == '40'
    # a painted sign's rules otherwise: a real leader is answered as before
    assert opinion.choose(reads_sixty, ['60', '80'], 4, 0.6, 1.2,
                          [('60', 12.0), ('80', 9.0)], lit_face=True) == '60'


def test_a_model_all_but_certain_answers_a_limit_it_has_real_crops_of() -> None:
    """:meth:`SecondOpinion.certain_choice` answers the model's best real label where it is
    a limit with real crops leading by the lead asked for; it overrules the correlation's
    leader only below ``overrule_below_psr``; a value without real crops with as many
    digits near or above the answer in the correlation withholds it, unless below it and
    dismissed by the model; the linear form never answers this way."""
    labels = real = ('60', '80', '90', '120', 'other_sign')
    network = dataclasses.replace(_network_opinion(labels, real),
                                  crop_labels=('60', '80', '120', 'other_sign'))
    dismissed = UNSEEN_RUNNER_UP_DISMISSED_SCORE - 0.0005
    certain_80 = np.asarray([-0.99, 0.995, dismissed, -1.0, -1.0])
    led_by_80 = [('80', 9.0), ('60', 8.5), ('90', 6.0), ('120', 5.0)]
    assert network.certain_choice(certain_80, led_by_80, 1.98, 8.0) == '80'
    assert network.certain_choice(certain_80, led_by_80, 1.99, 8.0) is None  # lead 1.985
    # another leader: overruled only where its PSR is below overrule_below_psr
    led_by_60 = [('60', 7.5), ('80', 7.0), ('90', 6.0), ('120', 5.0)]
    assert network.certain_choice(certain_80, led_by_60, 1.98, 8.0) == '80'
    assert network.certain_choice(certain_80, led_by_60, 1.98, 7.5) is None
    # 90 (composites only) below the answer within UNSEEN_RUNNER_UP_PSR: stands only
    # where the model dismisses it
    near_90 = [('80', 9.0), ('90', 9.0 - UNSEEN_RUNNER_UP_PSR / 2), ('60', 6.0), ('120', 5.0)]
    assert network.certain_choice(certain_80, near_90, 1.98, 8.0) == '80'
    sees_90 = certain_80.copy()
    sees_90[2] = UNSEEN_RUNNER_UP_DISMISSED_SCORE + 0.0005
    assert network.certain_choice(sees_90, near_90, 1.98, 8.0) is None
    # 90 above the answer: withheld, dismissed or not (the held-out value leading)
    led_by_90 = [('90', 7.5), ('80', 7.0), ('60', 6.0), ('120', 5.0)]
    assert network.certain_choice(certain_80, led_by_90, 1.98, 8.0) is None
    # a 3-digit value without crops does not guard a 2-digit answer
    with_130 = ('60', '80', '130', '120', 'other_sign')
    three_digits = dataclasses.replace(network, labels=with_130, real_labels=with_130)
    near_130 = [('80', 9.0), ('130', 9.0), ('60', 6.0), ('120', 5.0)]
    assert three_digits.certain_choice(sees_90, near_130, 1.98, 8.0) == '80'
    # a best label known from composites only, or not a limit: never
    certain_90 = np.asarray([-1.0, -1.0, 0.995, -1.0, -1.0])
    assert network.certain_choice(certain_90, [('90', 9.0), ('80', 5.0)], 1.98, 8.0) is None
    certain_other = np.asarray([-1.0, -1.0, -1.0, -1.0, 0.995])
    assert network.certain_choice(certain_other, led_by_80, 1.98, 8.0) is None
    assert _opinion(labels, real).certain_choice(certain_80, led_by_80, 1.98, 8.0) is None


def test_a_certain_model_dismisses_a_close_value_without_crops_only_when_surer() -> None:
    """Within UNSEEN_RUNNER_UP_CLOSE_PSR below the answer, a value without real crops counts
    as dismissed by :meth:`SecondOpinion.certain_choice` only at a score of at most
    CERTAIN_CLOSE_RUNNER_UP_DISMISSED_SCORE (a held-out 60 at 0.09 PSR below an 80, scored
    -0.99901, was read as 80); further below, UNSEEN_RUNNER_UP_DISMISSED_SCORE suffices."""
    labels = real = ('60', '80', 'other_sign')
    network = dataclasses.replace(_network_opinion(labels, real),
                                  crop_labels=('80', 'other_sign'))
    assert CERTAIN_CLOSE_RUNNER_UP_DISMISSED_SCORE < UNSEEN_RUNNER_UP_DISMISSED_SCORE
    between = (CERTAIN_CLOSE_RUNNER_UP_DISMISSED_SCORE + UNSEEN_RUNNER_UP_DISMISSED_SCORE) / 2
    dismissed = np.asarray([between, 0.998, -1.0])     # the model's lead 1.998 (over 60)
    close = [('80', 9.6), ('60', 9.6 - UNSEEN_RUNNER_UP_CLOSE_PSR / 5)]
    further = [('80', 9.6), ('60', 9.6 - 2 * UNSEEN_RUNNER_UP_CLOSE_PSR)]
    assert network.certain_choice(dismissed, close, 1.98, 8.0) is None
    assert network.certain_choice(dismissed, further, 1.98, 8.0) == '80'
    surer = np.asarray([CERTAIN_CLOSE_RUNNER_UP_DISMISSED_SCORE - 0.00005, 0.998, -1.0])
    assert network.certain_choice(surer, close, 1.98, 8.0) == '80'
