from django.urls import path

from racing import live_views, timing_views, views

app_name = "racing"
urlpatterns = [
    path("races/", views.race_list, name="race-list"),
    path("races/submit/", views.submission_create, name="submission-create"),
    path("races/submissions/", views.submission_list, name="submission-list"),
    path("races/submissions/<int:pk>/", views.submission_detail, name="submission-detail"),
    path("races/submissions/<int:pk>/video", views.submission_video, name="submission-video"),
    path("races/community/new/", views.community_race_create, name="community-race-create"),
    path("races/community/<slug:slug>/", views.community_race_manage, name="community-race-manage"),
    path(
        "races/community/<slug:slug>/delete",
        views.community_race_delete,
        name="community-race-delete",
    ),
    path(
        "races/community/<slug:slug>/close", views.community_race_close, name="community-race-close"
    ),
    path(
        "races/community/<slug:slug>/remove/<int:user_pk>",
        views.community_race_remove,
        name="community-race-remove",
    ),
    path(
        "races/community/<slug:slug>/readmit/<int:user_pk>",
        views.community_race_readmit,
        name="community-race-readmit",
    ),
    path(
        "races/community/<slug:slug>/invitation",
        views.community_race_invitation_renew,
        name="community-race-invitation-renew",
    ),
    path("races/invite/<str:token>/", views.event_join, name="event-join"),
    path("leaderboards/", views.leaderboard_list, name="leaderboard-list"),
    path("leaderboards/<slug:slug>/", views.leaderboard, name="leaderboard"),
    path("seasons/<int:pk>/", views.season_standings, name="season-standings"),
    path("events/<slug:slug>/timekeeper/", timing_views.timekeeper, name="timekeeper"),
    path(
        "events/<slug:slug>/timekeeper/signal",
        timing_views.timekeeper_signal,
        name="timekeeper-signal",
    ),
    path(
        "events/<slug:slug>/timekeeper/token",
        timing_views.timekeeper_token,
        name="timekeeper-token",
    ),
    path(
        "events/<slug:slug>/timekeeper/racers",
        timing_views.timekeeper_racers,
        name="timekeeper-racers",
    ),
    path(
        "events/<slug:slug>/timekeeper/runs/<int:pk>/",
        timing_views.timed_run,
        name="timed-run",
    ),
    path(
        "events/<slug:slug>/timekeeper/runs/<int:pk>/laps",
        timing_views.lap_edit,
        name="lap-edit",
    ),
    path("events/<slug:slug>/winner", timing_views.winner, name="winner"),
    path("events/<slug:slug>/broadcast/", timing_views.broadcast, name="broadcast"),
    path(
        "events/<slug:slug>/broadcast/state", timing_views.broadcast_state, name="broadcast-state"
    ),
    path("api/timing/<slug:slug>/", timing_views.device, name="timing-device"),
    path("events/<slug:slug>/live/", live_views.live_race, name="live-race"),
    path("events/<slug:slug>/live/open", live_views.live_race_open, name="live-race-open"),
    path("events/<slug:slug>/live/launch", live_views.live_race_launch, name="live-race-launch"),
    path(
        "events/<slug:slug>/live/entries/<int:pk>/leave",
        live_views.live_entry_leave,
        name="live-entry-leave",
    ),
    path(
        "events/<slug:slug>/live/entries/<int:pk>/<str:action>",
        live_views.live_entry_action,
        name="live-entry-action",
    ),
]
